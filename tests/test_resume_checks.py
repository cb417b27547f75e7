"""`benchlab run --resume` checks the schedule stored in the run file like a new one, before the bench moves.

Issue 12: a killed run whose stored steps were edited to 9000 rpm and 2000 N*m was driven there on resume
(exit 0), and a malformed stored schedule ended in a TypeError (exit 1). Now either is exit 2, one line naming
the file, the step and the field, and the bench is never even opened.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import pytest

import benchlab.runner.session as session
from benchlab.cli import main
from benchlab.runfile import read_progress
from benchlab.runner.session import RunRequest, execute
from crashed import abort_on_silent_load  # tests/crashed.py
from protocols.limits import BenchLimits
from protocols.schedule import Step
from sim_bench.bench import SimulatedBench

STEPS = (Step("open", 20.0, 1500.0, 0.0, 0.0, 0), Step("launch", 10.0, 1500.0, 45.0, 500.0, 1),
         Step("drive", 20.0, 1500.0, 45.0, 500.0, 1), Step("open", 20.0, 1500.0, 0.0, 500.0, 1))


@pytest.fixture(scope="module")
def aborted_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run aborted in cycle 0 by a silent load controller: resumable, cycle 1 still to do."""
    out = tmp_path_factory.mktemp("aborted") / "run.h5"
    code, summary = abort_on_silent_load(out, STEPS)
    assert code == 1 and summary.status == "aborted"
    return out


def _copy(aborted_run: Path, tmp_path: Path) -> Path:
    out = tmp_path / "run.h5"
    shutil.copy(aborted_run, out)
    shutil.copy(aborted_run.with_suffix(".blf"), out.with_suffix(".blf"))
    return out


def _edit_schedule(path: Path, edit: Callable[[list[dict[str, Any]]], Any]) -> None:
    """Rewrite /schedule's steps_json with `edit(rows)` (its return value, if not None, replaces the rows)."""
    with h5py.File(path, "r+") as f:
        rows = json.loads(f["schedule"].attrs["steps_json"])
        new = edit(rows)
        f["schedule"].attrs["steps_json"] = new if isinstance(new, str) else json.dumps(rows if new is None else new)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _set(step: int, field: str, value: Any) -> Callable[[list[dict[str, Any]]], None]:
    def edit(rows: list[dict[str, Any]]) -> None:
        rows[step][field] = value
    return edit


def _drop(step: int, field: str) -> Callable[[list[dict[str, Any]]], None]:
    def edit(rows: list[dict[str, Any]]) -> None:
        del rows[step][field]
    return edit


@pytest.mark.parametrize("edit, field, expected", [
    (_set(1, "engine_speed_rpm", 9000.0), "/schedule step 1 engine_speed_rpm", "9000 rpm outside 0..3000"),
    (_set(2, "clutch_torque_nm", 2000.0), "/schedule step 2 clutch_torque_nm", "2000 N*m outside 0..100"),
    (_set(3, "load_torque_nm", -5000.0), "/schedule step 3 load_torque_nm", "beyond ±600"),
    (_set(0, "engine_speed_rpm", 9000.0), "/schedule step 0 engine_speed_rpm", "outside"),  # a step already done
    (_set(1, "duration_s", 60.0), "/schedule step 1 duration_s", "slip time"),
    (_set(2, "phase", "warp"), "/schedule step 2 phase", "unknown phase"),
    (_set(2, "until", [{"channel": "T_flywheel", "op": ">=", "value": 105.0}]), "/schedule step 2 until[0].value",
     "too close to its interlock"),
    (_set(1, "engine_speed_rpm", "fast"), "/schedule step 1 engine_speed_rpm", "a finite number, got 'fast'"),
    (_set(1, "engine_speed_rpm", float("nan")), "/schedule step 1 engine_speed_rpm", "a finite number"),
    (_set(1, "load_torque_nm", None), "/schedule step 1 load_torque_nm", "a finite number, got None"),
    (_set(1, "cycle", "one"), "/schedule step 1 cycle", "an integer"),
    (_set(1, "clutch_torque_nm", True), "/schedule step 1 clutch_torque_nm", "a finite number, got True"),
    (_set(2, "until", [{"channel": "T_air", "op": ">=", "value": "hot"}]), "/schedule step 2 until[0].value",
     "a finite number"),
    (_set(2, "until", [{"channel": "T_air", "op": ">="}]), "/schedule step 2 until[0].value", "missing"),
    (_set(2, "until", "T_air >= 50"), "/schedule step 2 until", "a list"),
    (_set(2, "point", [["rpm"]]), "/schedule step 2 point[0]", "a pair"),
    (_drop(1, "engine_speed_rpm"), "/schedule step 1 engine_speed_rpm", "present (missing)"),
    (_set(1, "turbo", 1.0), "/schedule step 1 turbo", "unknown field"),
    (lambda rows: rows[:1] + [[1, 2, 3]] + rows[2:], "/schedule step 1", "an object with the fields"),
    (lambda rows: {"steps": rows}, "/schedule", "a list of steps"),
    (lambda rows: "[{\"phase\": ", "/schedule steps_json", "JSON"),
], ids=["9000rpm", "2000Nm", "load", "done-step", "slip-time", "phase", "target", "str", "nan", "null", "cycle",
        "bool", "cond-str", "cond-missing", "until-str", "point", "missing", "extra", "row-list", "not-list",
        "not-json"])
def test_a_bad_stored_schedule_is_exit_2_and_the_bench_never_moves(aborted_run, tmp_path, capsys, opened_benches,
                                                                    edit, field, expected):
    out = _copy(aborted_run, tmp_path)
    _edit_schedule(out, edit)
    before = _digest(out)
    code = main(["run", "--resume", str(out), "--bench", "sim", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"{out}: {field}: " in lines[0] and expected in lines[0], lines[0]
    assert opened_benches == []  # no bench, no set-point
    assert _digest(out) == before and not out.with_suffix(".resume1.blf").exists()


def test_limits_of_the_resuming_bench_apply(aborted_run, tmp_path, opened_benches):
    """A schedule within the default limits is refused by a bench with tighter ones (the limits are not the file's)."""
    out = _copy(aborted_run, tmp_path)
    before = _digest(out)
    with pytest.raises(session.InputError) as exc:
        execute(RunRequest("", out, resume=True, bench=SimulatedBench(limits=BenchLimits(max_engine_speed_rpm=1000.0)),
                           install_signals=False))
    assert exc.value.field == "/schedule step 0 engine_speed_rpm" and opened_benches == []
    assert _digest(out) == before


def test_an_untouched_schedule_resumes_and_moves_the_bench(aborted_run, tmp_path, opened_benches):
    """The control: the same file unedited is resumed, set-points are sent, the run completes."""
    out = _copy(aborted_run, tmp_path)
    with h5py.File(out, "r") as f:
        setpoint_rows_before = int(read_progress(f)["rows/setpoints"])
    code, summary = execute(RunRequest("", out, resume=True, install_signals=False))
    assert code == 0 and summary.status == "complete" and len(opened_benches) == 1
    with h5py.File(out, "r") as f:
        assert int(read_progress(f)["rows/setpoints"]) > setpoint_rows_before
        assert max(f["raw/setpoints/engine_speed"][:]) == pytest.approx(1500.0)
