"""A stale reading is an unknown reading: every interlock input that falls silent makes the bench safe (issue 12).

Each case silences one input of the simulated bench through its own transport (port unplugged, instrument
muted, radio silent, controller silent) and checks, from the run file alone, that the safe state was
commanded within 2 s of the moment the channel's newest valid reading became older than its maximum age.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from protocols.limits import BenchLimits
from protocols.safety import SAFE_STATES
from protocols.schedule import Step
from sim_bench.bench import SimulatedBench
from sim_bench.faults import Fault

IDLE = BenchLimits().idle_speed_rpm
SAFE = (IDLE, 0.0, 1.0, 0.0)
STEPS = (Step("open", 30.0, 2000.0, 0.0, 0.0, 0), Step("launch", 10.0, 2000.0, 60.0, 100.0, 1),
         Step("drive", 40.0, 2000.0, 60.0, 100.0, 1), Step("open", 60.0, 1500.0, 0.0, 100.0, 2),
         Step("open", 60.0, 1000.0, 0.0, 100.0, 3))
# channel -> (raw stream, column whose finite values are that channel's valid readings)
SOURCE = {"T_air": ("instrument", "T_air"), "T_flywheel": ("node", "T_flywheel_1"),
          "clutch_speed": ("can_load", "speed"), "engine_speed": ("can_drive", "speed"),
          "clutch_torque": ("can_clutch", "torque")}


def _run(tmp_path, faults, **limits):
    path = tmp_path / "run.h5"
    sim = SimulatedBench(faults=faults, options={"dropouts": False}, limits=BenchLimits(resume_after_s=5.0, **limits))
    code, summary = execute(RunRequest("custom", path, steps=STEPS, bench=sim, install_signals=False))
    with h5py.File(path, "r") as f:
        events = [(float(t), k.decode(), d.decode()) for t, k, d in
                  zip(f["events/time"][:], f["events/kind"][:], f["events/detail"][:])]
        sp = f["raw/setpoints"]
        setpoints = (sp["time"][:], np.column_stack([sp[c][:] for c in ("engine_speed", "clutch_torque",
                                                                         "clutch_open", "load_torque")]))
    return code, summary, events, setpoints, path


def _last_valid_before(path, channel, t):
    stream, column = SOURCE[channel]
    with h5py.File(path, "r") as f:
        times, values = f[f"raw/{stream}/time"][:], f[f"raw/{stream}/{column}"][:]
    ok = np.isfinite(values) & (times <= t)
    return float(times[ok][-1])


def _first_safe_after(setpoints, t, safe_rows=SAFE):
    times, rows = setpoints
    safe = np.all(rows == safe_rows, axis=1) & (times >= t - 1e-9)
    return float(times[safe][0])


def _first_safe_state(channel):
    """The set-points of the first safe state the table gives `stale_<channel>` (a lost drive stops it, issue 29)."""
    state = SAFE_STATES[BenchLimits().reaction(f"stale_{channel}").stages[0]]
    return (IDLE if state.engine == "idle" else 0.0, 0.0, 1.0, 0.0)


@pytest.mark.parametrize("channel, faults, age, extra", [
    ("T_air", [Fault(40.0, "instrument_disconnect")], 5.0, {}),
    ("T_air", [Fault(47.5, "instrument_mute")], 3.0, {}),
    ("T_flywheel", [Fault(52.0, "radio_silence", duration_s=1e4)], 4.0, {}),
    ("clutch_speed", [Fault(45.0, "controller_silent", target="load")], 0.5, {"heartbeat": False}),
    ("engine_speed", [Fault(36.3, "controller_silent", target="drive")], 1.5, {"heartbeat": False}),
    # over-temperature while the air sensor is stale: the heater is on, the instrument gone at the same time
    ("T_air", [Fault(60.0, "air_heater", 15000.0), Fault(60.0, "instrument_disconnect")], 2.0, {}),
], ids=["instrument unplugged", "instrument muted", "node silent", "load controller silent",
        "drive controller silent", "air over-temperature, sensor stale"])
def test_a_silent_input_trips_its_stale_interlock_and_the_bench_goes_safe_within_2_s(tmp_path, channel, faults,
                                                                                       age, extra):
    code, summary, events, setpoints, path = _run(tmp_path, faults, max_age_s={channel: age},
                                                  on_interlock="abort", **extra)
    assert code == 1 and summary.status == "aborted" and load_run(path).attrs["status"] == "aborted"
    trips = [(t, d) for t, k, d in events if k == "interlock"]
    assert trips and trips[0][1].startswith(f"stale_{channel}:") and "(abort)" in trips[0][1], trips
    t_fault = faults[0].at_s
    t_limit = _last_valid_before(path, channel, trips[0][0]) + age
    assert t_limit > t_fault  # the fault silenced the channel; it was fresh before
    t_safe = _first_safe_after(setpoints, t_limit, _first_safe_state(channel))
    assert 0.0 <= t_safe - t_limit <= 2.0, (t_limit, t_safe)
    assert trips[0][0] - t_limit <= 2.0


def test_hold_keeps_the_bench_safe_until_the_input_is_back_then_the_run_goes_on(tmp_path):
    faults = [Fault(45.0, "instrument_disconnect"), Fault(70.0, "instrument_reconnect")]
    code, summary, events, (times, rows), path = _run(tmp_path, faults, actions={"stale_T_air": "hold"})
    assert code == 0 and summary.status == "complete"
    kinds = [k for _, k, _ in events]
    t_trip = next(t for t, k, d in events if k == "interlock" and d.startswith("stale_T_air:") and "(hold)" in d)
    t_clear = next(t for t, k, _ in events if k == "interlock_cleared")
    assert 70.0 + 5.0 <= t_clear < 70.0 + 5.0 + 3.0  # back at 70 s, plus resume_after_s
    held = (times >= t_trip) & (times < t_clear)
    assert held.any() and np.all(rows[held] == SAFE)  # nothing but the safe state while held
    assert kinds.index("interlock") < kinds.index("cycle_skipped") and "run_complete" in kinds
    assert np.any((times > t_clear) & ~np.all(rows == SAFE, axis=1))  # the next cycle commands again


def test_an_input_that_never_comes_back_ends_a_hold_as_aborted(tmp_path):
    faults = [Fault(45.0, "radio_silence", duration_s=1e4)]
    code, summary, events, _, path = _run(tmp_path, faults, max_wait_s=20.0)
    assert code == 1 and summary.status == "aborted"
    aborted = [d for _, k, d in events if k == "run_aborted"]
    assert aborted and "stale_T_flywheel" in aborted[0] and "did not clear" in aborted[0]


def test_every_reading_starts_fresh_on_a_healthy_run(tmp_path):
    code, summary, events, _, _ = _run(tmp_path, [], max_age_s={"clutch_speed": 0.05, "T_air": 1.5})
    assert code == 0 and not [d for _, k, d in events if k == "interlock"]
