"""Protocols as data: schedules, limits, dry runs and bench files, all before anything moves."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.cli import main
from benchlab.errors import InputError
from benchlab.runner.config import load_bench_config
from protocols.catalog import build
from protocols.cooldown_sweep import parse_grid
from protocols.limits import BenchLimits, check_schedule, launch_estimate
from protocols.schedule import Step, step_from_dict
from protocols.table1 import table1_schedule

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "bench.toml"


def test_protocols_are_reproducible_checkable_data():
    for name in ("table1", "cooldown-sweep", "validation"):
        a, b = build(name, seed=4, limits=BenchLimits()), build(name, seed=4, limits=BenchLimits())
        assert a.steps == b.steps and a.steps
        assert check_schedule(a.steps, BenchLimits()) == []  # built for the bench: no draw it cannot launch
        assert all(step_from_dict(s.as_dict()) == s for s in a.steps)
    assert build("table1", seed=5).steps != build("table1", seed=4).steps


def test_validation_has_long_varying_cooldowns_and_fresh_table1_draws():
    steps = build("validation", seed=4).steps
    long_ = [s for s in steps if s.label == "validation_cooldown"]
    by_cycle = {}
    for s in long_:
        by_cycle.setdefault(s.cycle, []).append(s)
    assert len(by_cycle) == 3
    for segs in by_cycle.values():
        assert sum(s.duration_s for s in segs if s.phase != "launch") > 120
        assert len({(s.engine_speed_rpm, s.phase) for s in segs if s.phase != "launch"}) > 1
    table1 = [s for s in steps if s.label == "table1"]
    own = table1_schedule(4, n_cycles=len({s.cycle for s in table1}))
    assert [s.engine_speed_rpm for s in table1] != [s.engine_speed_rpm for s in own]


def test_cooldown_sweep_grid_and_steps():
    assert parse_grid("1000:1, 1500:0, 2000:0:500") == ((1000.0, 1, 0.0), (1500.0, 0, None), (2000.0, 0, 500.0))
    for bad in ("1000", "1000:2", "x:1", "1000:1:300", ""):
        with pytest.raises(ValueError):
            parse_grid(bad)
    steps = build("cooldown-sweep", grid="1000:1,2000:0:500").steps
    assert [s.phase for s in steps] == ["heat", "launch", "drive", "heat", "launch", "open"]
    assert steps[0].until[0].op == "steady" and steps[2].until[0].describe() == "T_flywheel <= 60"
    assert steps[4].engine_speed_rpm == 1500.0  # shaft brought to 2000 - 500 rpm before opening


def test_limits_catch_what_the_bench_must_not_do():
    limits = BenchLimits(max_slip_time_s=8.0, max_clutch_torque_nm=60.0)
    problems = check_schedule(table1_schedule(1, n_cycles=5), limits)
    assert any("slip time" in p for p in problems) and any("clutch torque 65" in p for p in problems)
    t, energy, synced = launch_estimate(Step("launch", 10.0, 1500.0, 45.0, 500.0), BenchLimits())
    assert synced and t == pytest.approx(4.19, abs=0.02) and energy == pytest.approx(14.8e3, rel=0.02)
    _, _, synced = launch_estimate(Step("launch", 10.0, 1500.0, 30.0, 500.0), BenchLimits())
    assert not synced


def test_dry_run_prints_checks_and_estimates(capsys):
    assert main(["run", "cooldown-sweep", "--bench", "sim", "--dry-run", "--grid", "1000:1,1000:0"]) == 0
    out = capsys.readouterr().out
    assert "steady at 70" in out and "estimated" in out and "within the bench limits" in out
    assert main(["run", "table1", "--bench", "sim", "--dry-run", "--cycles", "2"]) == 0


def test_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["run", "nonsense", "--bench", "sim", "--out", str(tmp_path / "x.h5")]) == 2
    assert main(["run", "cooldown-sweep", "--bench", "sim", "--grid", "1000:7", "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "--grid" in err[1]
    assert not (tmp_path / "x.h5").exists()


def test_example_bench_file_loads():
    cfg = load_bench_config(EXAMPLE)
    assert cfg.instrument_channels[101] == "T_air" and cfg.can["interface"] == "socketcan"
    assert cfg.instrument_calibration[101].r0 == 1000.12 and cfg.limits.on_interlock == "hold"


@pytest.mark.parametrize("edit, field", [
    (("url = \"/dev/ttyUSB0\"", "url = 5"), "instrument.url"),
    (("101 = \"T_air\"", "101 = \"T_oil\""), "instrument.channels.101"),
    (("max_air_c = 80.0", "max_air_c = -1"), "limits.max_air_c"),
    (("on_interlock = \"hold\"", "on_interlock = \"pray\""), "limits.on_interlock"),
    (("T_air = 5.0 ", "T_air = 3600.0 "), "limits.max_age_s.T_air"),
    (("clutch_torque = 0.5", "clutch_torque = -0.5"), "limits.max_age_s.clutch_torque"),
    (("clutch_torque = 0.5", "T_oil = 0.5"), "limits.max_age_s.T_oil"),
    (("stale_T_air = \"hold\"", "stale_T_air = \"wait\""), "limits.actions.stale_T_air"),
    (("stale_T_air = \"hold\"", "stale_oil = \"hold\""), "limits.actions.stale_oil"),
    (("interface = \"socketcan\"", "interface = \"udp_multicast\""), "can.interface"),
    (("[drivetrain]", "[drivetrane]"), "drivetrane"),
    (("r0 = 999.87", "r0 = \"x\""), "node.calibration.1.r0"),
])
def test_bad_bench_file_names_the_field(tmp_path, capsys, edit, field):
    path = tmp_path / "bench.toml"
    path.write_text(EXAMPLE.read_text().replace(*edit))
    with pytest.raises(InputError) as exc:
        load_bench_config(path)
    assert exc.value.field == field
    assert main(["run", "table1", "--bench", str(path), "--out", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert field in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "r.h5").exists()


def test_unknown_condition_channel_is_a_problem_not_a_default():
    from protocols.limits import BenchLimits, check_schedule
    from protocols.schedule import Condition, Step

    step = Step("open", 600.0, 1000.0, cycle=0, until=(Condition("T_flywheel_typo", "<=", 60.0),), estimate_s=300.0)
    problems = check_schedule((step,), BenchLimits())
    assert len(problems) == 1 and "T_flywheel_typo" in problems[0] and "T_flywheel, T_air" in problems[0]


def test_one_step_interpreter_plays_the_schedule_for_the_runner_and_the_batch_simulator(tmp_path):
    """The runner's commanded set-points and the batch simulator's drivetrain both follow `setpoints`."""
    import h5py
    import numpy as np

    from benchlab.runner.session import RunRequest, execute
    from protocols.schedule import setpoints
    from sim_bench.bench import SimulatedBench
    from sim_bench.faults import parse_fault
    from sim_bench.virtual_run import drive_schedule

    # a launch that synchronises (drive clamped) and one that does not (drive stays open: the slip limit): on the
    # bench a stuck clutch holds back a launch the plan accepts (the plan refuses one that cannot synchronise); the
    # batch simulator has no faults, so there the second launch is one that cannot
    steps = (Step("open", 20.0, 1500.0, 0.0, 0.0, 0), Step("launch", 8.0, 2000.0, 70.0, 100.0, 0),
             Step("drive", 20.0, 2000.0, 70.0, 100.0, 0), Step("launch", 3.0, 2500.0, 40.0, 140.0, 1),
             Step("drive", 20.0, 2500.0, 40.0, 140.0, 1), Step("open", 20.0, 1000.0, 0.0, 50.0, 1))
    path = tmp_path / "run.h5"
    stuck = parse_fault("stuck_clutch@41.5:value=10,duration_s=5")  # the second launch starts at about 41.3 s
    code, _ = execute(RunRequest("custom", path, steps=steps, install_signals=False,
                                 bench=SimulatedBench(faults=(stuck,), options={"dropouts": False})))
    assert code == 0
    with h5py.File(path, "r") as f:
        sp = f["raw/setpoints"]
        rows = [tuple(float(sp[c][i]) for c in ("engine_speed", "clutch_torque", "clutch_open", "load_torque"))
                for i in range(len(sp["time"]))]
    synced = (True, True, True, True, False, False)
    played = [tuple(float(v) for v in setpoints(s, ok)) for s, ok in zip(steps, synced)]
    expected = [row for i, row in enumerate(played) if i == 0 or row != played[i - 1]]  # changes are recorded
    commanded = [r for r in rows if r[0] != BenchLimits().idle_speed_rpm or r[2] == 0.0]  # without safe states
    assert commanded == expected
    stalled = steps[:3] + (Step("launch", 3.0, 2500.0, 10.0, 140.0, 1), Step("drive", 20.0, 2500.0, 10.0, 140.0, 1),
                           steps[5])
    truth, events = drive_schedule(stalled, 0.01)
    outcome = [e["event"] for e in events if e["event"] in ("synchronised", "slip_time_limit")]
    assert outcome == ["synchronised", "slip_time_limit"]
    open_after_stall = truth["clutch_state"][-int(40.0 / 0.01):]
    assert np.all(open_after_stall == 0.0)  # the stalled cycle's drive stays open in the batch simulator too
