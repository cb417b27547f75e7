"""The runner on the simulated bench (drivers over sim:// serial URLs and an in-process CAN bus).

Same seed, same /aligned; every interlock tripped by an injected fault leaves the bench safe; SIGTERM
closes the file as aborted; the friction energy taken from a poll's status frames in bulk is the energy frame by
frame.
"""

from __future__ import annotations

import math
import shutil
import signal
import subprocess
import sys
import time
import types

import h5py
import numpy as np
import pytest

from benchlab.runfile import load_events, load_run
from host_lag import HostLag
from benchlab.drivetrain import friction_power
from benchlab.progress import Progress, Task
from benchlab.runner.devices import BenchStatus
from benchlab.runner.session import RunRequest, execute
from drivers.can_bench import CanBlock
from drivers.can_signals import CLAMP_OPEN, CLAMP_SLIPPING
from protocols.limits import BenchLimits, with_launch_estimates
from protocols.schedule import Step, duration_s
from sim_bench.bench import SimulatedBench
from sim_bench.faults import Fault

IDLE = BenchLimits().idle_speed_rpm
REALTIME_SLACK_S = 0.3  # the real-time launch's margin: 2 s to reach 1900 rpm, which takes ~1.1 s of synchronising


def _events(path):
    with h5py.File(path, "r") as f:
        g = f["events"]
        return [(float(t), k.decode(), d.decode()) for t, k, d in zip(g["time"][:], g["kind"][:], g["detail"][:])]


def test_same_seed_same_aligned_data(tmp_path):
    runs = []
    for name in ("a.h5", "b.h5"):
        code, summary = execute(RunRequest("table1", tmp_path / name, seed=11, cycles=3, install_signals=False))
        assert code == 0 and summary.cycles_done == 3
        runs.append(load_run(tmp_path / name))
    a, b = runs
    assert list(a.columns) == list(b.columns) and len(a) == len(b) > 9000  # 3 cycles, >= 30 s cool-down each
    for c in a.columns:
        np.testing.assert_array_equal(a[c].to_numpy(), b[c].to_numpy())
    assert a.attrs["status"] == "complete"
    # physically sensible: launches heat the clutch, friction power only while clamped
    assert np.nanmax(a["friction_power"]) > 1000 and np.all(a["friction_power"][a["clutch_state"] == 0] == 0)
    with h5py.File(tmp_path / "a.h5", "r") as f:  # every raw stream in the order it was measured
        for name, stream in f["raw"].items():
            assert np.all(np.diff(stream["time"][()]) >= 0), name
    kinds = [k for _, k, _ in _events(tmp_path / "a.h5")]
    assert kinds.count("cycle_start") == 3 and "engagement_start" in kinds and "synchronised" in kinds
    c, _ = execute(RunRequest("table1", tmp_path / "c.h5", seed=12, cycles=3, install_signals=False))
    assert not np.array_equal(load_run(tmp_path / "c.h5")["T_flywheel"].to_numpy()[:20000],
                              a["T_flywheel"].to_numpy()[:20000], equal_nan=True)


STEPS = (Step("open", 40.0, 2000.0, 0.0, 0.0, 0), Step("launch", 10.0, 2000.0, 60.0, 100.0, 1),
         Step("drive", 30.0, 2000.0, 60.0, 100.0, 1), Step("open", 30.0, 1500.0, 0.0, 100.0, 2))


def _run_with(tmp_path, faults, action="abort", **limits):
    lim = BenchLimits(on_interlock=action, resume_after_s=5.0, **limits)
    sim = SimulatedBench(faults=faults, options={"dropouts": False}, limits=lim)
    code, summary = execute(RunRequest("custom", tmp_path / "run.h5", steps=STEPS, bench=sim, install_signals=False))
    return code, summary, _events(tmp_path / "run.h5")


def _assert_safe(physics, path):
    engine, clamped, torque, load = physics._setpoints
    assert (engine, clamped, torque, load) == (IDLE, False, 0.0, 0.0)  # what the controllers apply
    with h5py.File(path, "r") as f:
        sp = f["raw/setpoints"]
        last = [float(sp[c][-1]) for c in ("engine_speed", "clutch_torque", "clutch_open", "load_torque")]
        assert last == [IDLE, 0.0, 1.0, 0.0]  # what the runner commanded last
        assert f.attrs["status"] == "aborted"


@pytest.mark.parametrize("fault, kind", [
    (Fault(3.0, "flywheel_heater", 30000.0), "flywheel_over_temperature"),
    (Fault(3.0, "air_heater", 15000.0), "air_over_temperature"),
    (Fault(3.0, "controller_silent", target="load"), "controller_lost"),
    (Fault(3.0, "controller_fault", 2.0, target="clutch"), "controller_lost"),
    (Fault(3.0, "radio_silence", duration_s=30.0), "stale_T_flywheel"),
    (Fault(3.0, "stuck_clutch", 10.0, 25.0), "slip_time"),
    (Fault(3.0, "stuck_clutch", 70.0, 25.0), "slip_energy"),
])
def test_each_interlock_trips_on_its_fault_and_leaves_the_bench_safe(tmp_path, opened_benches, fault, kind):
    code, summary, events = _run_with(tmp_path, [fault])
    interlocks = [d for _, k, d in events if k == "interlock"]
    assert code == 1 and summary.status == "aborted"
    assert interlocks and interlocks[0].startswith(kind), interlocks
    t_fault = fault.at_s
    t_trip = next(t for t, k, _ in events if k == "interlock")
    assert t_fault <= t_trip < t_fault + (40.0 if kind == "flywheel_over_temperature" else 20.0)
    if fault.kind != "stuck_clutch":  # a stuck clutch obeys again only when the fault ends
        [opened] = opened_benches
        _assert_safe(opened["sim"].physics, tmp_path / "run.h5")
        status = opened["bench"].status
        assert status.clamp_state == CLAMP_OPEN


def test_interlock_hold_then_next_cycle(tmp_path):
    faults = [Fault(3.0, "radio_silence", duration_s=15.0)]
    code, summary, events = _run_with(tmp_path, faults, action="hold")
    kinds = [k for _, k, _ in events]
    assert code == 0 and summary.status == "complete"
    assert kinds.index("interlock") < kinds.index("interlock_cleared") < kinds.index("cycle_skipped")
    cleared = next(t for t, k, _ in events if k == "interlock_cleared")
    assert cleared >= 3.0 + 15.0 + 5.0 - 0.6  # silence over, plus resume_after_s
    starts = [t for t, k, _ in events if k == "cycle_start"]
    skipped = next(t for t, k, _ in events if k == "cycle_skipped")
    assert len(starts) == 3 and starts[0] < skipped <= starts[1]  # rest of cycle 0 skipped, 1 and 2 run
    assert "dropout_start" in kinds and "dropout_end" in kinds


@pytest.mark.parametrize("after_s", [0.0, 1.5])  # 0: while the run file is being made, before the loop starts
def test_sigterm_puts_bench_safe_and_file_aborted(after_s, tmp_path):
    out = tmp_path / "term.h5"
    proc = subprocess.Popen([sys.executable, "-m", "benchlab.cli", "run", "table1", "--bench", "sim", "--duration",
                             "7200", "--out", str(out), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 600  # start-up on a loaded machine; what is tested starts with the run file
    while time.time() < deadline and not out.exists() and proc.poll() is None:
        time.sleep(0.005)
    assert out.exists(), proc.communicate(timeout=60)
    time.sleep(after_s)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, stderr
    run = load_run(out)
    assert run.attrs["status"] == "aborted"
    events = _events(out)
    aborted = [d for _, k, d in events if k == "run_aborted"]
    assert len(aborted) == 1 and "SIGTERM" in aborted[0]
    with h5py.File(out, "r") as f:
        sp = f["raw/setpoints"]
        assert [float(sp[c][-1]) for c in ("engine_speed", "clutch_torque", "clutch_open", "load_torque")] == \
            [IDLE, 0.0, 1.0, 0.0]
    assert b"run aborted" in stdout


def test_instrument_faults_are_events_and_gaps_only_while_they_last(tmp_path):
    faults = [Fault(10.0, "instrument_error", -310.0, target="System error"),
              Fault(20.0, "instrument_disconnect"), Fault(30.0, "instrument_reconnect")]
    code, summary, events = _run_with(tmp_path, faults, action="hold")
    assert code == 0
    kinds = [(t, k, d) for t, k, d in events if k == "instrument_error"]
    assert any("-310" in d for _, _, d in kinds)  # the error queue entry, read and reported
    assert any(20.0 <= t < 31.0 and "disconnected" in d for t, _, d in kinds)
    run = load_run(tmp_path / "run.h5")
    t, air = run["time"].to_numpy(), run["T_air"].to_numpy()
    assert np.isnan(air[(t > 21.6) & (t < 30.0)]).all()  # nothing invented while disconnected
    assert np.isfinite(air[(t > 2.0) & (t < 20.0)]).all() and np.isfinite(air[(t > 33.0) & (t < 100.0)]).all()


def test_validation_protocol_runs(tmp_path):
    code, summary = execute(RunRequest("validation", tmp_path / "v.h5", seed=3, cycles=1, install_signals=False))
    assert code == 0 and summary.cycles_done == 4
    run = load_run(tmp_path / "v.h5")
    events = _events(tmp_path / "v.h5")
    starts = [t for t, k, d in events if k == "step_start" and "validation_cooldown" in d]
    assert len(starts) >= 9
    assert np.nanmax(run["T_flywheel"]) > 69.0  # each long cool-down starts hot
    # the report's long cool-downs: their steps in /schedule, whatever the event text, and in an old file
    new, reworded, old = _validation_cooldowns_of(tmp_path / "v.h5", tmp_path)
    assert [(cycle, text) for cycle, _, _, text in new] == [
        (0, "open → open → open"), (1, "launch → drive → drive → drive"), (2, "open → launch → drive → open")]
    cycle_starts = {e.cycle: e.time for e in load_events(tmp_path / "v.h5") if e.kind == "cycle_start"}
    for cycle, t0, t1, _ in new:  # from the heat's end to the next cycle's start
        assert cycle_starts[cycle] < t0 < t1 == cycle_starts[cycle + 1]
    assert reworded == old == new


def _validation_cooldowns_of(path, tmp_path):
    """The report's long cool-downs of the run at `path`, of a copy with the detail text reworded and of a copy
    as written before events carried `step` and `reason`."""
    from benchlab.report.index import validation_cooldowns

    reworded, old = tmp_path / "reworded.h5", tmp_path / "old.h5"
    shutil.copy(path, reworded)
    shutil.copy(path, old)
    with h5py.File(reworded, "r+") as f:
        f["events/detail"][...] = b"reworded for people"
    with h5py.File(old, "r+") as f:
        del f["events/step"], f["events/reason"]
    return [validation_cooldowns(p) for p in (path, reworded, old)]


def _launch_and_open(path, clock=None, stop_first: bool = False):
    """A launch to 2000 rpm and an open step through the drivers against the emulators, on `clock` (the real one),
    or on the simulated bench's own clock (`stop_first`: a stop asked before the run starts); the run summary."""
    from benchlab.acquire import RunWriter
    from benchlab.runner.devices import BenchConfig, DriverBench
    from benchlab.runner.engine import STATE_FIELDS, Runner
    from sim_bench.bench import SimBench, SimBenchConfig

    sim = SimBench(SimBenchConfig(seed=1, dropouts=False), clock=clock)
    cfg = BenchConfig(sim.urls["instrument"], sim.urls["node"], {"interface": "sim"}, instrument_timeout_s=0.5,
                      tick_s=0.1, fast_tick_s=0.02)
    bench = DriverBench(cfg, sim.clock, bus=sim.driver_bus, service=sim.service)
    steps = (Step("launch", 2.0, 2000.0, 65.0, 100.0, 0), Step("open", 1.0, 2000.0, 0.0, 100.0, 0))
    writer = RunWriter(path, bench.layout, protocol="rt", planned_s=5, state_fields=STATE_FIELDS,
                       durable=clock is not None)
    try:
        # an interlock aborts instead of holding (30 s to 30 min): where the host starves the emulators of a core
        # on the real clock a device falls silent, and the run ends at once, its verdict the host's (tests/host_lag.py)
        runner = Runner(bench, sim.clock, steps, writer, BenchLimits(on_interlock="abort"), tick_s=0.1,
                        fast_tick_s=0.02, dt=0.01)
        if stop_first:
            runner.request_stop("SIGINT", 130)
        summary = runner.run()
        writer.close(summary.status)
        return summary
    finally:
        bench.close()
        sim.close()


def test_a_stop_asked_before_the_run_starts_commands_no_step(tmp_path):
    """A Ctrl-C while the bench opens (the session notes it until the runner exists) ends the run before its first
    step sets anything."""
    summary = _launch_and_open(tmp_path / "run.h5", stop_first=True)
    assert summary.status == "aborted" and summary.exit_code == 130
    kinds = [e.kind for e in load_events(tmp_path / "run.h5")]
    assert "run_aborted" in kinds and not {"step_start", "engagement_start", "cycle_start"} & set(kinds)


def test_real_time_loop_on_emulated_devices(tmp_path):
    """The hardware path (real clock, durable writes) against the emulators running on wall-clock time."""
    from benchlab.runner.clock import RealClock

    # no warm-up: the bench's and the simulated bench's kernels are primed before the loop (test_loop_compile)
    with HostLag() as lag:
        summary = _launch_and_open(tmp_path / "rt.h5", RealClock())
    # the steps last at least the launch's synchronisation (~1.1 s) plus the open step, on the real clock;
    # no upper bound: a loaded machine only makes the loop late, never the run shorter. The launch reaches its
    # speed in the step's time where the host gives the emulators' threads a core: a wait longer than the
    # step's margin (tests/host_lag.py) is the host's, not the loop's
    with lag.judged(REALTIME_SLACK_S):
        assert summary.status == "complete" and summary.sim_s >= 1.5, summary.lines()
        run = load_run(tmp_path / "rt.h5")
        assert np.nanmax(run["clutch_speed"]) > 1900 and np.nanmax(run["friction_power"]) > 5000


def _frame_by_frame(st: BenchStatus, t: float, values: dict, gear: float) -> None:
    """Reference: one status frame at its time, the power held since the newest frame before it."""
    if t > st.t_frame:
        st.friction_energy_j += st.friction_power * (t - st.t_frame)
        st.t_frame = t
    elif math.isnan(st.t_frame):
        st.t_frame = t
    st.engine_speed = values.get("drive.speed", st.engine_speed)
    st.clutch_speed = values["load.speed"] * gear if "load.speed" in values else st.clutch_speed
    if "clutch.torque" in values:
        st.clutch_torque, st.clamp_state = values["clutch.torque"], int(values["clutch.clamp_state"])
    power = friction_power(st.clutch_torque, st.engine_speed, st.clutch_speed, st.clamp_state == CLAMP_SLIPPING)
    st.friction_power = power if power == power else 0.0


def test_friction_energy_of_a_polls_frames_in_bulk_equals_frame_by_frame():
    """Status frames of the three controllers, interleaved, some late (older than a frame already taken), over
    many polls: BenchStatus.take_status on the blocks gives the energy and values of taking each frame in
    the order received."""
    rng = np.random.default_rng(5)
    signals = {"drive": ("drive.speed",), "clutch": ("clutch.torque", "clutch.clamp_state"), "load": ("load.speed",)}
    for _ in range(100):
        bulk, reference, t0 = BenchStatus(), BenchStatus(), 0.0
        for _ in range(5):
            counts = {c: int(rng.integers(0, 6)) for c in signals}
            n = sum(counts.values())
            if not n:
                continue
            times = np.sort(t0 + rng.uniform(0.0, 0.1, n))
            t0 = times[-1]
            if rng.random() < 0.3:
                times = rng.permutation(times)  # received out of time order
            arrival, blocks, frames, used = rng.permutation(n), [], [], 0
            for controller, keys in signals.items():
                index = np.sort(arrival[used:used + counts[controller]])
                used += counts[controller]
                if not len(index):
                    continue
                n_frames = len(index)
                columns = {"drive.speed": rng.uniform(700, 3000, n_frames), "clutch.torque": rng.uniform(0, 80, n_frames),
                           "clutch.clamp_state": rng.integers(0, 3, n_frames).astype(float),
                           "load.speed": rng.uniform(0, 200, n_frames)}
                matrix = np.column_stack([columns[k] for k in keys])
                blocks.append(CanBlock(controller, controller, index, times[index], matrix, keys))
                frames += [(i, times[i], dict(zip(keys, row))) for i, row in zip(index, matrix.tolist())]
            for _, t, values in sorted(frames, key=lambda f: f[0]):
                _frame_by_frame(reference, t, values, 15.0)
            bulk.take_status(blocks, 15.0)
            for name in ("engine_speed", "clutch_speed", "clutch_torque", "clamp_state", "friction_power", "t_frame"):
                a, b = getattr(bulk, name), getattr(reference, name)
                assert a == b or (math.isnan(a) and math.isnan(b)), name
            assert bulk.friction_energy_j == pytest.approx(reference.friction_energy_j, rel=1e-12, abs=1e-12)


class _RecordedTask(Task):
    """A progress bar that keeps what the runner reports: each advance and each note."""

    def __init__(self) -> None:
        self.advances: list[float] = []
        self.notes: list[str] = []

    def advance(self, amount: float = 1.0) -> None:
        self.advances.append(amount)

    def note(self, text: str) -> None:
        self.notes.append(text)


def test_progress_bar_moves_forward_through_the_steps_in_order(tmp_path, monkeypatch):
    from benchlab.runner import engine

    task = _RecordedTask()
    progress = Progress()
    monkeypatch.setattr(progress, "task", lambda what, total, unit="it": task)
    wall = iter(range(10**9))  # a second of wall time per look at the clock: every tick reports
    monkeypatch.setattr(engine, "time", types.SimpleNamespace(perf_counter=lambda: float(next(wall))))
    steps = (Step("open", 10.0, 1500.0, 0.0, 0.0, 0), Step("launch", 5.0, 1500.0, 45.0, 500.0, 1),
             Step("drive", 10.0, 1500.0, 45.0, 500.0, 1), Step("open", 10.0, 1500.0, 0.0, 500.0, 1))
    code, _ = execute(RunRequest("custom", tmp_path / "run.h5", steps=steps, progress=progress, install_signals=False,
                                 bench=SimulatedBench(options={"dropouts": False})))
    assert code == 0
    steps = with_launch_estimates(steps, BenchLimits())  # as planned: the launch at its time to synchronise
    assert sum(task.advances) == pytest.approx(duration_s(steps))  # the whole plan once the run is done
    shown = [note.split()[2] for note in task.notes]  # "cycle 1/2 open ..." -> the phase of the step shown
    assert [p for i, p in enumerate(shown) if i == 0 or p != shown[i - 1]] == [s.phase for s in steps]
    planned_before = np.concatenate([[0.0], np.cumsum([s.expected_s for s in steps])])
    index = np.cumsum([i > 0 and p != shown[i - 1] for i, p in enumerate(shown)])  # the step each note shows
    done = np.cumsum(task.advances[:len(task.notes)])  # a note follows each advance but the final one
    assert np.all(planned_before[index] - 1e-9 <= done) and np.all(done <= planned_before[index + 1] + 1e-9)


def test_a_run_whose_every_cycle_was_skipped_is_not_complete(tmp_path):
    steps = (Step("open", 40.0, 2000.0, 0.0, 0.0, 0),)  # one cycle; the silence holds it, then it is skipped
    lim = BenchLimits(on_interlock="hold", resume_after_s=5.0)
    sim = SimulatedBench(faults=[Fault(3.0, "radio_silence", duration_s=15.0)], options={"dropouts": False}, limits=lim)
    code, summary = execute(RunRequest("custom", tmp_path / "run.h5", steps=steps, bench=sim, install_signals=False))
    kinds = [k for _, k, _ in _events(tmp_path / "run.h5")]
    assert "cycle_skipped" in kinds and "run_aborted" in kinds and "run_complete" not in kinds
    assert code == 1 and summary.status == "aborted" and "every cycle skipped" in summary.reason
    assert load_run(tmp_path / "run.h5").attrs["status"] == "aborted"
