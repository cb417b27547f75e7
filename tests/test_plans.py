"""Plans that tell the truth: what the dry-run accepts synchronises on the simulated bench, and the estimate is the
duration the run takes (issue 34)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchlab.cli import main
from benchlab.runfile import load_events, load_run, load_schedule
from benchlab.runner.session import RunRequest, execute
from protocols.catalog import build
from protocols.limits import LAUNCH_TORQUE_MARGIN, BenchLimits, check_schedule, launch_problem
from protocols.schedule import Step, duration_s
from protocols.table1 import table1_schedule
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant


def _run(tmp_path, name: str, bench="sim", **options) -> tuple[float, float, list[str]]:
    """(planned s, run's duration s, event kinds) of `name` on the simulated bench (its reference plant by default)."""
    out = tmp_path / f"{name}.h5"
    code, summary = execute(RunRequest(name, out, bench=bench, install_signals=False, **options))
    assert code == 0 and summary is not None and summary.status == "complete"
    planned = duration_s(load_schedule(out))  # the plan the run itself made (and its dry-run prints)
    run = load_run(out)
    return planned, float(run["time"].iloc[-1] - run["time"].iloc[0]), [e.kind for e in load_events(out)]


def test_a_launch_that_cannot_carry_its_load_is_named_with_the_numbers():
    why = launch_problem(Step("launch", 10.0, 1000.0, 30.0, 500.0), BenchLimits())
    assert why is not None and "450 N*m" in why and f"margin {LAUNCH_TORQUE_MARGIN:g}" in why
    assert launch_problem(Step("launch", 10.0, 1000.0, 45.0, 500.0), BenchLimits()) is None
    # carries its load but slips past its maximum slip time at this speed
    assert "within its 2 s" in launch_problem(Step("launch", 2.0, 2000.0, 30.0, 300.0), BenchLimits())


def test_the_dry_run_drops_table1_draws_that_cannot_synchronise_with_a_note(capsys):
    raw = table1_schedule(1, duration_s=3600.0)
    stalls = [s for s in raw if s.phase == "launch" and launch_problem(s, BenchLimits()) is not None]
    assert stalls  # the paper's Table 1 holds such draws (30 N*m against 500 N*m at a ratio of 15)
    assert main(["run", "table1", "--bench", "sim", "--dry-run", "--duration", "3600"]) == 0
    out = capsys.readouterr().out
    notes = [line for line in out.splitlines() if line.startswith("plan: ")]
    assert notes and all("dropped: launch cannot synchronise" in n for n in notes)
    assert "schedule within the bench limits" in out and "on the simulated bench" in out
    accepted = build("table1", 1, None, 3600.0, None, BenchLimits())
    assert check_schedule(accepted.steps, BenchLimits()) == [] and len(accepted.notes) == len(notes)


def test_a_custom_schedule_with_a_launch_that_stalls_is_refused(tmp_path):
    steps = (Step("open", 10.0, 1500.0, 0.0, 0.0, 0), Step("launch", 10.0, 1500.0, 30.0, 500.0, 1))
    problems = check_schedule(steps, BenchLimits())
    assert len(problems) == 1 and "step 1 (cycle 1, launch): launch cannot synchronise" in problems[0]
    with pytest.raises(Exception, match="clutch_torque_nm"):
        execute(RunRequest("custom", tmp_path / "r.h5", steps=steps, install_signals=False))
    assert not (tmp_path / "r.h5").exists()


def test_no_launch_of_an_accepted_table1_trips_the_slip_limit_and_the_estimate_holds(tmp_path):
    planned, took, kinds = _run(tmp_path, "table1", duration_s=400.0)  # seed 1: two of its first draws dropped
    assert build("table1", 1, None, 400.0, None, BenchLimits()).notes
    assert "slip_time_limit" not in kinds and kinds.count("synchronised") == kinds.count("cycle_start")
    assert took >= 400.0  # --duration is a floor
    assert took == pytest.approx(planned, rel=0.10)


# A sweep's heat-ups and cool-downs are simulated on the plant the run uses (protocols.estimates.timed):
# on the reference plant (the default) the paper's closed forms planned 1108 s for a run of 2319 s.
@pytest.mark.parametrize("name, options, plant", [("cooldown-sweep", {"grid": "1000:1,1500:0"}, "reference"),
                                                  ("validation", {"cycles": 2}, "reference")])
def test_the_closed_loop_protocols_take_the_time_the_plan_says(tmp_path, name, options, plant):
    bench = SimulatedBench(ThermalPlant()) if plant == "paper" else "sim"
    planned, took, kinds = _run(tmp_path, name, bench=bench, **options)
    assert "timeout" not in kinds and "slip_time_limit" not in kinds
    assert took == pytest.approx(planned, rel=0.10)


def test_duration_is_a_floor_for_what_diagnose_needs(tmp_path):
    from benchlab.commands.diagnose import load_diagnosed_runs
    from benchlab.diagnose.engine import MIN_DURATION_S
    from benchlab.model.catalog import resolve_model

    out = tmp_path / "t1.h5"
    assert main(["run", "table1", "--bench", "sim", "--duration", f"{MIN_DURATION_S:g}", "--out", str(out), "-q"]) == 0
    assert len(load_diagnosed_runs([str(out)], resolve_model("linear", "--model"))) == 1  # not refused as too short


def _estimated_s(capsys, *argv: str) -> float:
    """The expected duration `benchlab run ... --dry-run` prints (s)."""
    assert main(["run", "cooldown-sweep", "--dry-run", "--grid", "1000:1,1500:0", *argv]) == 0
    return float(re.search(r"estimated (\d+) s", capsys.readouterr().out).group(1))


def test_a_hardware_sweep_is_timed_on_the_parameter_files_model(params_file, tmp_path, capsys):
    """Issue 46: on a hardware bench a sweep's heat-ups and cool-downs are timed on the model of `--params` (the
    sim bench's estimate on its own plant); without one, the paper's closed forms; a model that cannot be driven
    by the bench's channels is one line, exit 2."""
    bench = str(Path(__file__).parents[1] / "examples" / "bench.toml")
    on_model = _estimated_s(capsys, "--bench", bench, "--params", str(params_file))
    on_paper_plant = _estimated_s(capsys, "--bench", "sim", "--plant", "paper")  # the same network and values
    assert on_model == pytest.approx(on_paper_plant, abs=1.0)
    from benchlab.model.catalog import resolve_model
    from benchlab.model.params import ModelParams, load_params, save_params

    heavy = load_params(params_file)  # a clutch twice as heavy: heats and cools twice as slowly
    heavy.update(C_P=2 * heavy["C_P"], C_F=2 * heavy["C_F"])
    save_params(tmp_path / "heavy.json", heavy)
    assert _estimated_s(capsys, "--bench", bench, "--params", str(tmp_path / "heavy.json")) > 1.6 * on_model
    assert _estimated_s(capsys, "--bench", bench) != on_model  # without a parameter file: the closed forms

    text = (Path(__file__).parents[1] / "models" / "clutch-nonlinear.toml").read_text()
    assert "a2*exp(b2*engine_speed)" in text
    (tmp_path / "geared.toml").write_text(text.replace("a2*exp(b2*engine_speed)", "a2*exp(b2*gearbox_speed)"))
    geared = resolve_model(str(tmp_path / "geared.toml"))  # its open clutch reads a channel the bench has not
    save_params(tmp_path / "geared.json", ModelParams(geared, dict(load_params(params_file))))
    assert main(["run", "cooldown-sweep", "--dry-run", "--bench", bench, "--params", str(tmp_path / "geared.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "geared.json" in err and "gearbox_speed" in err, err
