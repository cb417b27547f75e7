"""/events carry the step of /schedule they belong to and a `reason` to match (the interlock's name, why a step
ended); files written before the `step` or `reason` column still read.

A short simulated run, aborted by an interlock and resumed: every step_start names its own row of /schedule,
every event of a step lies inside it, the interlock and step ends carry their reason. Files without `step`
(written with h5py, or an old run resumed) read with step -1 through load_events, the live view and the
cool-down analysis; files without `reason` read with the reason their detail text gave, and a reworded detail
changes nothing the readers find.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from benchlab.identify.cooldown import segments
from benchlab.errors import InputError
from benchlab.runfile import event_steps, load_events, load_schedule
from benchlab.runfile.schema import END_CONDITION, END_SYNCHRONISED, END_TIME
from benchlab.runner.session import RunRequest, execute
from benchlab.watch.live import LiveRun
from crashed import abort_on_silent_load  # tests/crashed.py
from protocols.limits import BenchLimits, with_launch_estimates
from protocols.schedule import Step
from sim_bench.bench import SimulatedBench

STEPS = (Step("open", 10.0, 1500.0, 0.0, 0.0, 0), Step("launch", 5.0, 1500.0, 45.0, 500.0, 1),
         Step("drive", 10.0, 1500.0, 45.0, 500.0, 1), Step("open", 10.0, 1500.0, 0.0, 500.0, 1))
OLD_COLUMNS = ("time", "cycle", "kind", "detail")  # /events before `step`


@pytest.fixture(scope="module")
def aborted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run aborted in step 0 (cycle 0) by a silent load controller; cycle 1 (steps 1-3) still to do."""
    out = tmp_path_factory.mktemp("events") / "run.h5"
    code, _ = abort_on_silent_load(out, STEPS)
    assert code == 1
    return out


def _resumed(aborted: Path, tmp_path: Path, drop: tuple[str, ...] = ()) -> Path:
    out = tmp_path / "run.h5"
    shutil.copy(aborted, out)
    shutil.copy(aborted.with_suffix(".blf"), out.with_suffix(".blf"))
    with h5py.File(out, "r+") as f:  # as a file written before events carried these columns
        for column in drop:
            del f[f"events/{column}"]
    code, summary = execute(RunRequest("custom", out, resume=True, install_signals=False,
                                       bench=SimulatedBench(options={"dropouts": False})))
    assert code == 0 and summary.status == "complete"
    return out


def test_every_event_carries_the_step_it_happened_in(aborted, tmp_path):
    with h5py.File(aborted, "r") as f:
        assert f["events/step"].dtype == np.int64 and f["events/step"].attrs["units"] == "1"
    with h5py.File(aborted, "r") as f:
        assert f["events/reason"].dtype == np.dtype("S32") and f["events/reason"].attrs["units"] == ""
    first = load_events(aborted)
    stopped = {(e.kind, e.step) for e in first if e.kind in ("interlock", "run_aborted")}
    assert stopped == {("interlock", 0), ("run_aborted", 0)}  # the step the interlock interrupted
    assert [(e.kind, e.reason) for e in first if e.reason] == [("interlock", "controller_lost"),
                                                               ("interlock", "stale_clutch_speed")]
    out = _resumed(aborted, tmp_path)
    schedule, events = load_schedule(out), load_events(out)
    assert schedule == with_launch_estimates(STEPS, BenchLimits())  # as planned: the launch at its time to sync
    starts = [e for e in events if e.kind == "step_start"]
    assert [e.step for e in starts] == [0, 1, 2, 3]  # step 0 before the abort, then cycle 1 after the resume
    for e in starts:  # the row it names is the step that ran: its cycle and its phase (the runner's detail)
        assert e.cycle == schedule[e.step].cycle and e.detail.split()[0] == schedule[e.step].phase
    assert [e.step for e in events if e.kind == "step_end"] == [1, 2, 3]
    for e in events:  # why each step ended, as the text for people says it
        if e.kind == "step_end":
            assert e.reason in (END_TIME, END_CONDITION, END_SYNCHRONISED)
            assert e.detail == f"{schedule[e.step].phase}: {e.reason}"
    assert [(e.step, e.cycle) for e in events if e.kind == "resume"] == [(1, 0)]
    assert [e.step for e in events if e.kind == "cycle_start"] == [0, 1]
    assert [e.step for e in events if e.kind == "run_complete"] == [-1]
    spans = {e.step: [e.time, np.inf] for e in starts}
    for e in events:
        if e.kind == "step_end":
            spans[e.step][1] = e.time
    inside = [e for e in events if e.step >= 0 and e.kind != "resume"]
    assert any(e.kind == "engagement_start" for e in inside)  # events of the bench, not only the runner's own
    for e in inside:
        assert spans[e.step][0] <= e.time <= spans[e.step][1], e


def test_resuming_a_file_without_the_step_column_adds_it(aborted, tmp_path):
    out = _resumed(aborted, tmp_path, drop=("step", "reason"))
    events = load_events(out)
    resume = next(i for i, e in enumerate(events) if e.kind == "resume")
    assert resume > 0 and all(e.step == -1 for e in events[:resume])  # not known before the resume
    assert [e.step for e in events[resume:] if e.kind == "step_start"] == [1, 2, 3]
    # the reason of the events before the resume: from their detail text, written into the resumed file
    assert [(e.kind, e.reason) for e in events[:resume] if e.reason] == [("interlock", "controller_lost"),
                                                                         ("interlock", "stale_clutch_speed")]
    with h5py.File(out, "r") as f:
        assert f["events/reason"][:resume].tolist() == [e.reason.encode() for e in events[:resume]]


def _live_interlocks(path: Path) -> list[str]:
    """The interlocks the live view shows active at the end of the file."""
    live = LiveRun(path)
    try:
        return sorted(live.update(width=100)["status"]["interlocks"])
    finally:
        live.close()


def test_the_live_view_names_interlocks_by_reason_whatever_their_text_and_in_old_files(aborted, tmp_path):
    assert _live_interlocks(aborted) == ["controller_lost", "stale_clutch_speed"]  # the run ended held by both
    reworded, old = tmp_path / "reworded.h5", tmp_path / "old.h5"
    shutil.copy(aborted, reworded)
    shutil.copy(aborted, old)
    with h5py.File(reworded, "r+") as f:
        f["events/detail"][...] = b"tripped: see the log"
    with h5py.File(old, "r+") as f:  # as written before `reason`: the name from the text of then
        del f["events/reason"]
    assert _live_interlocks(reworded) == _live_interlocks(old) == ["controller_lost", "stale_clutch_speed"]


def _old_format(path: Path, events: list[tuple[float, int, str, str]], steps: tuple[Step, ...] = ()) -> Path:
    """A run file as written before /events had `step`, with h5py alone: /aligned, /events, /schedule."""
    n, dt = 200, 0.1
    with h5py.File(path, "w") as f:
        f.attrs.update(schema="benchlab-run/1", status="complete", protocol="cooldown-sweep")
        aligned = f.create_group("aligned")
        aligned.attrs["dt"] = dt
        for name, unit in (("time", "s"), ("T_air", "degC")):
            values = np.arange(n) * dt if name == "time" else np.full(n, 25.0)
            aligned.create_dataset(name, data=values).attrs["units"] = unit
        group = f.create_group("events")
        for j, (name, dtype, unit) in enumerate(zip(OLD_COLUMNS, ("f8", "i8", "S32", "S160"), ("s", "1", "", ""))):
            column = [e[j].encode() if isinstance(e[j], str) else e[j] for e in events]
            group.create_dataset(name, data=np.array(column, dtype=dtype)).attrs["units"] = unit
        f.create_group("schedule").attrs["steps_json"] = json.dumps([s.as_dict() for s in steps])
    return path


def test_a_file_without_step_and_reason_reads_with_step_minus_one_and_the_reason_its_text_gave(tmp_path):
    rows = [(0.0, 0, "cycle_start", ""), (0.0, 0, "step_start", "drive"),
            (1.0, 0, "interlock", "T_air_max: 80.2 degC above 80 (hold)"), (2.0, 0, "interlock_cleared", "T_air_max"),
            (3.0, 0, "cooldown_end", "condition; engine_speed=800"), (5.0, 0, "step_end", "drive: time"),
            (5.5, -1, "run_complete", "")]
    reasons = ["", "", "T_air_max", "", END_CONDITION, END_TIME, ""]
    path = _old_format(tmp_path / "old.h5", rows)
    assert [tuple(e) for e in load_events(path)] == [(*r, -1, why) for r, why in zip(rows, reasons)]
    live = LiveRun(path)
    try:
        answer = live.update(width=100, events_from=0)
        assert [(e["time"], e["cycle"], e["kind"], e["detail"], e["step"], e["reason"])
                for e in answer["events"]["items"]] == [(*r, -1, why) for r, why in zip(rows, reasons)]
    finally:
        live.close()


def test_old_files_step_starts_take_their_step_from_their_place_in_the_cycle(tmp_path):
    steps = (Step("open", 10.0, 800.0, cycle=0), Step("drive", 10.0, 800.0, cycle=0), Step("open", 10.0, 800.0, cycle=1))
    rows = [(0.0, 0, "cycle_start", ""), (0.0, 0, "step_start", ""), (9.0, 0, "engagement_start", ""),
            (10.0, 0, "step_start", ""), (12.0, 0, "resume", ""),  # killed in step 1, resumed: cycle 0 again
            (12.0, 0, "cycle_start", ""), (12.0, 0, "step_start", ""), (22.0, 0, "step_start", ""),
            (32.0, 1, "cycle_start", ""), (32.0, 1, "step_start", ""), (40.0, 1, "step_start", "")]
    events = load_events(_old_format(tmp_path / "old.h5", rows, steps))
    assert event_steps(events, steps) == [-1, 0, -1, 1, -1, -1, 0, 1, -1, 2, -1]  # cycle 1 has no second step
    stamped = [e._replace(step=5) if e.kind == "step_start" else e for e in events]
    assert event_steps(stamped, steps) == [5 if e.kind == "step_start" else -1 for e in events]  # a stored step wins


def test_cooldown_points_from_the_events_step_and_in_old_files_from_the_cycles_order(tmp_path):
    point = (("engine_speed", 800.0), ("clutch_state", 1.0), ("slip_speed", 0.0))
    steps = (Step("heat", 100.0, 900.0, cycle=0, label="heat", point=point),
             Step("drive", 100.0, 800.0, cycle=0, label="cooldown", point=point))
    old = [(0.0, 0, "cooldown_start", "engine_speed=800"), (9.0, 0, "cooldown_end", "condition; engine_speed=800")]
    assert segments(_old_format(tmp_path / "old.h5", old, steps)) == [(0, 0.0, 9.0, dict(point))]
    # a run killed in its cool-down and resumed runs the cycle again: two cooldown_starts, one step
    new = tmp_path / "new.h5"
    with h5py.File(_old_format(new, [(1.0, 0, "cooldown_start", ""), (4.0, 0, "resume", ""),
                                     (5.0, 0, "cooldown_start", ""), (9.0, 0, "cooldown_end", "condition")],
                               steps), "r+") as f:
        f["events"].create_dataset("step", data=np.array([1, 1, 1, 1], dtype="i8")).attrs["units"] = "1"
    assert segments(new) == [(0, 5.0, 9.0, dict(point))]
    with h5py.File(new, "r+") as f:  # a step that is not a cool-down: no point to take
        f["events/step"][...] = 0
    with pytest.raises(InputError) as exc:
        segments(new)
    assert exc.value.field == "/schedule" and "as step 0" in str(exc.value)
