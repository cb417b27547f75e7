"""The bench's safety case (issue 29, docs/safety.md): each rehearsal reaches the safe state the table gives its fault,
and the simulated plant's /truth stays within the bench's limits plus the documented overshoot.

The measured rows of docs/safety.md come from these rehearsals (`python -m tests.test_safety_case` prints them).
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from benchlab.cli import main
from benchlab.runfile import load_events, load_run, load_truth

TODAY_STUCK_J = 4.94e6  # what the fixed safe state (drive idling against the stuck clutch) dissipated after the trip
MAX_CLUTCH_C = 300.0  # no clutch above this in any rehearsal (issue 29)


def rehearse(tmp_path: Path, *argv: str) -> tuple[int, Path]:
    """`benchlab run` on the simulated bench with `argv` (protocol, faults, ...); its exit code and run file."""
    out = tmp_path / "rehearsal.h5"
    code = main(["run", *argv, "--bench", "sim", "--seed", "1", "--out", str(out), "-q"])
    return code, out


def measured(path: Path) -> dict[str, float]:
    """What a rehearsal reached between its first trip and the end of that hold (interlock_cleared, else the run's
    end): the trip's time, the time until friction power stayed 0 (s), the friction energy (J, /aligned) and
    /truth's maxima (degC) in that window, and /truth's maxima over the whole run (`run_max_*`)."""
    run, events, truth = load_run(path), load_events(path), load_truth(path)
    trips = [e.time for e in events if e.kind == "interlock"]
    t_trip = min(trips) if trips else np.inf
    t_end = min([e.time for e in events if e.kind == "interlock_cleared" and e.time >= t_trip] or [np.inf])
    t, power = run.time.to_numpy(), np.nan_to_num(run.friction_power.to_numpy())
    dt = float(np.median(np.diff(t)))
    window = (t >= t_trip) & (t <= t_end)
    slipping = t[window & (power > 0)]
    out = {"t_trip": t_trip, "energy_after_trip_j": float(power[window].sum() * dt),
           "t_to_safe_s": float(slipping[-1] + dt - t_trip) if len(slipping) else 0.0}
    rows = (truth.time.to_numpy() >= t_trip) & (truth.time.to_numpy() <= t_end)
    for name in ("T_pressure_plate", "T_flywheel", "T_air"):
        out[f"max_{name}"] = float(truth[name].to_numpy()[rows].max()) if rows.any() else np.nan
        out[f"run_max_{name}"] = float(truth[name].max())
    return out


def last_setpoints(path: Path) -> tuple[float, ...]:
    with h5py.File(path, "r") as f:
        sp = f["raw/setpoints"]
        return tuple(float(sp[c][-1]) for c in ("engine_speed", "clutch_torque", "clutch_open", "load_torque"))


def test_a_stuck_clutch_stops_the_drive_instead_of_idling_against_it(tmp_path):
    """The issue's rehearsal: the first safe state (open, idle) does not stop the friction power, so the drive stops
    with the load holding, and the run ends there (the clutch needs looking at): ≤ 5 % of today's 4.94 MJ."""
    code, path = rehearse(tmp_path, "table1", "--duration", "2400", "--fault",
                          "stuck_clutch@70:value=100,duration_s=600")
    assert code == 1 and load_run(path).attrs["status"] == "aborted"
    events = load_events(path)
    escalated = [e for e in events if e.kind == "safe_state_escalated"]
    assert escalated and escalated[0].detail.endswith("open_idle -> stop_hold"), escalated
    aborted = [e.detail for e in events if e.kind == "run_aborted"]
    assert aborted and "did not open" in aborted[0] and "stop_hold" in aborted[0]
    drive, torque, clutch_open, _ = last_setpoints(path)
    assert drive == 0.0 and torque == 0.0 and clutch_open == 1.0  # the drive stays stopped when the run ends
    m = measured(path)
    assert m["energy_after_trip_j"] <= 0.05 * TODAY_STUCK_J, m
    assert m["run_max_T_pressure_plate"] < MAX_CLUTCH_C, m


#: Rehearsals of the simulated bench (issue 29): id -> (argv after the protocol, the first interlock, its safe state,
#: the latest the trip may come (s of run time), what ends the run: "complete", "aborted" or "alarm").
REHEARSALS = {
    "drive controller hung (alive counter frozen)": (
        ["--duration", "300", "--fault", "controller_frozen@70:target=drive",
         "--fault", "controller_unfrozen@90:target=drive"], "stale_engine_speed", "open_stop", 70.0 + 0.5 + 1.5,
        "complete"),
    "clutch controller hung during an engagement": (
        ["--duration", "300", "--fault", "controller_frozen@3:target=clutch",
         "--fault", "controller_unfrozen@20:target=clutch"], "stale_clutch_torque", "stop_hold", 3.0 + 0.5 + 1.5,
        "complete"),
    "clutch controller silent during an engagement": (
        ["--duration", "300", "--fault", "controller_silent@3:target=clutch",
         "--fault", "controller_back@20:target=clutch"], "controller_lost", "open_idle", 3.0 + 1.5, "complete"),
    "node radio lost during a slip": (
        ["--duration", "300", "--fault", "radio_silence@3:duration_s=30"], "stale_T_flywheel", "open_idle",
        3.0 + 10.0 + 1.5, "complete"),
    "host stall of 30 s during an engagement": (
        ["--duration", "300", "--fault", "host_stall@3:duration_s=30"], "controller_lost", "stop_hold", 33.0 + 1.5,
        "complete"),
    "flywheel heater the bench cannot switch off": (
        ["--duration", "600", "--fault", "flywheel_heater@20:value=5000"], "flywheel_over_temperature", "open_idle",
        math.inf, "alarm"),
    "instrument lost with the air heater on": (
        ["--duration", "600", "--fault", "air_heater@20:value=15000", "--fault", "instrument_disconnect@22"],
        "stale_T_air", "open_idle", 22.0 + 5.0 + 1.5, "alarm"),
}


@pytest.mark.parametrize("name", list(REHEARSALS))
def test_every_rehearsal_reaches_the_safe_state_its_fault_asks_for(name, tmp_path):
    argv, first, state, latest, ending = REHEARSALS[name]
    code, path = rehearse(tmp_path, "table1", *argv)
    events = load_events(path)
    trips = [e for e in events if e.kind == "interlock"]
    assert trips and trips[0].reason == first and trips[0].time <= latest, [(e.time, e.detail) for e in trips]
    assert trips[0].detail.endswith(f"safe state {state}")
    aborted = [e.detail for e in events if e.kind == "run_aborted"]
    if ending == "complete":
        assert code == 0 and not aborted and "interlock_cleared" in {e.kind for e in events}
    else:
        assert code == 1 and aborted and aborted[0].startswith("alarm:") and "cannot switch off" in aborted[0]
    m = measured(path)
    assert m["run_max_T_pressure_plate"] < MAX_CLUTCH_C, m
    alive_errors = [e for e in events if e.kind == "controller_alive_error"]
    assert len(alive_errors) <= 2 + (events[-1].time - events[0].time) / 10  # summarised, not one per frame


@pytest.mark.parametrize("fault, says", [
    ("node_clock_drift@10:value=-5000", "clock_remapped"),  # 0.5 % slow: the map would lag by seconds
    ("node_clock_drift@10:value=3000", None),  # fast: the offset falls with every frame, no re-map needed
    ("node_clock_jump@100:value=-5", "node_reset"),  # back: the gateway takes it for a new node clock
    ("node_clock_jump@100:value=5", "clock_remapped")])
def test_a_node_clock_off_beyond_its_allowance_is_mapped_anew_and_says_so(fault, says, tmp_path):
    """A node clock 0.5 % slow (or fast, or jumping) is mapped anew and /events says so: its samples are never
    placed seconds away from when they were measured, and T_flywheel never goes stale while frames arrive."""
    code, path = rehearse(tmp_path, "table1", "--duration", "600", "--fault", fault)
    events = load_events(path)
    assert code == 0 and (says is None or says in {e.kind for e in events})
    assert not [e for e in events if e.kind == "interlock"], [e.detail for e in events if e.kind == "interlock"]
    with h5py.File(path, "r") as f:
        t, seq = f["raw/node/time"][:], f["raw/node/seq"][:].astype(float)
    true = t[0] + (seq - seq[0]) * 0.05  # the node measures every period_s of bench time (seq counts lost frames too)
    assert np.max(np.abs(t - true)) <= 0.5 + 0.15, np.max(np.abs(t - true))  # REMAP_S + a slow tick


@pytest.mark.parametrize("fault, missing", [("controller_silent@0:target=drive", "engine_speed"),
                                            ("instrument_disconnect@0", "T_air"),
                                            ("controller_frozen@0:target=load", "clutch_speed")])
def test_nothing_moves_before_every_interlock_input_is_alive(fault, missing, tmp_path):
    """The readiness gate: with an input dead from the start, only the safe state is ever commanded (a launch
    used to be commanded at 1.0 s with the drive silent), and the run ends saying which input never came."""
    code, path = rehearse(tmp_path, "table1", "--duration", "300", "--fault", fault)
    events = load_events(path)
    aborted = [e.detail for e in events if e.kind == "run_aborted"]
    assert code == 1 and aborted and aborted[0].startswith("not ready:") and missing in aborted[0], aborted
    assert "inputs_ready" not in {e.kind for e in events} and "cycle_start" not in {e.kind for e in events}
    with h5py.File(path, "r") as f:
        sp = f["raw/setpoints"]
        assert np.all(sp["clutch_open"][:] == 1.0) and np.all(sp["clutch_torque"][:] == 0.0)
        assert np.all(sp["engine_speed"][:] <= 800.0) and np.all(sp["load_torque"][:] == 0.0)


def _table_rows(workdir: Path) -> list[str]:
    """docs/safety.md's measured columns: one row per rehearsal above, as Markdown."""
    cases = {"stuck clutch (issue's run)": (["--duration", "2400", "--fault", "stuck_clutch@70:value=100,duration_s=600"],),
             **REHEARSALS}
    rows = []
    for i, (name, case) in enumerate(cases.items()):
        code, path = rehearse(workdir / str(i), "table1", *case[0]) if (workdir / str(i)).mkdir() is None else (0, "")
        m, events = measured(path), load_events(path)
        trips = [e for e in events if e.kind == "interlock"]
        end = [e.detail for e in events if e.kind in ("run_aborted", "run_complete")] or [""]
        rows.append(f"| {name} | {trips[0].reason if trips else '-'} at {m['t_trip']:.2f} s | "
                    f"{trips[0].detail.rsplit('safe state ', 1)[-1] if trips else '-'} | {m['t_to_safe_s']:.2f} s | "
                    f"{m['energy_after_trip_j'] / 1e3:.1f} kJ | {m['max_T_pressure_plate']:.0f} / "
                    f"{m['max_T_flywheel']:.0f} / {m['max_T_air']:.0f} | {m['run_max_T_pressure_plate']:.0f} | exit {code}: {end[0] or 'complete'} |")
    return rows


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        print("\n".join(_table_rows(Path(tmp))))


def test_a_silent_clutch_actuator_leaves_no_phantom_engagement(tmp_path):
    """Issue 29: with the actuator silent mid-launch, its held torque and state used to be integrated into an
    engagement that tripped slip_time and slip_energy on energy never dissipated."""
    code, path = rehearse(tmp_path, "table1", "--duration", "300", "--fault", "controller_silent@3:target=clutch",
                          "--fault", "controller_back@20:target=clutch")
    events = load_events(path)
    assert code == 0 and not {e.reason for e in events if e.kind == "interlock"} & {"slip_time", "slip_energy"}
    ends = [e for e in events if e.kind == "engagement_end"]
    assert ends and ends[0].time <= 3.0 + 0.5 + 1.0  # ends once the actuator's frames are stale (max age + a tick)


def test_a_host_stall_leaves_the_clutch_to_the_controllers_own_time_out(tmp_path):
    """Issue 29: with the PC silent for 30 s mid-launch the clutch slipped 32.65 s; the controllers' command time-out
    (3 cycles) now opens it and stops the drive at its deadline. Nothing is received meanwhile, so /truth tells: the
    plate warms 0.43 K over the stall (2.38 K when the time-out never applied the safe set-points)."""
    code, path = rehearse(tmp_path, "table1", "--duration", "300", "--fault", "host_stall@3:duration_s=30")
    truth = load_truth(path)
    t, plate = truth.time.to_numpy(), truth.T_pressure_plate.to_numpy()
    stall = (t >= 3.0) & (t <= 34.0)
    assert code == 0 and plate[stall].max() - plate[np.searchsorted(t, 3.0)] <= 1.0
