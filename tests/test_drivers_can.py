"""Bench CAN: DBC contents, exact frames, codec vs cantools, watchdog events, fault injection, safe state."""

import itertools
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import can_signals as sig
from drivers.can_bench import CanBench
from drivers.can_codec import MessageCodec
from drivers.errors import CanBusError, CanConfigError
from sim_bench.emulators import CanBenchEmulator, ManualClock, SimCanBus

DB = cantools.database.load_file(str(sig.BENCH_DBC))
_chan = itertools.count()

MOTOROLA_DBC = """VERSION ""
BS_:
BU_: A
BO_ 1024 Vendor: 8 A
 SG_ Speed : 7|16@0- (0.25,-10) [-8000|8000] "rpm" A
 SG_ Odd : 19|11@0+ (1,0) [0|2047] "" A
 SG_ Flag : 24|1@1+ (1,0) [0|1] "" A
 SG_ Tail : 39|20@0- (0.001,0) [-500|500] "" A
"""


@pytest.fixture
def buses():
    name = f"t{next(_chan)}"
    pc, ctrl = can.Bus(interface="virtual", channel=name), can.Bus(interface="virtual", channel=name)
    yield pc, ctrl
    pc.shutdown()
    ctrl.shutdown()


def frames(bus: can.BusABC) -> list[tuple[int, bytes]]:
    out = []
    while (m := bus.recv(timeout=0)) is not None:
        out.append((m.arbitration_id, bytes(m.data)))
    return out


def test_dbc_describes_every_controller() -> None:
    for m in DB.messages:
        assert m.cycle_time, m.name
    for prefix in ("DM", "CA", "LM"):
        for suffix in ("FaultCode", "Alive", "State"):
            assert any(s.name == f"{prefix}_{suffix}" for m in DB.messages for s in m.signals)
    names = {m.name for m in DB.messages}
    assert {"EmergencyStop", "Heartbeat_PC", "Heartbeat_DriveMotor", "Heartbeat_ClutchActuator",
            "Heartbeat_LoadMachine"} <= names
    for message, signal in sig.BENCH_SIGNALS.values():
        DB.get_message_by_name(message).get_signal_by_name(signal)


def test_command_frames_table(buses) -> None:
    pc, ctrl = buses
    clock = ManualClock()
    bench = CanBench(pc, clock=clock)
    table = [
        (lambda: bench.set_drive_speed(1500), [(0x100, "b80b010000000010")]),
        (lambda: bench.set_clutch_torque(45), [(0x110, "9411020000000010")]),
        (lambda: bench.set_load_torque(-300), [(0x120, "48f4010000000010")]),
        (lambda: bench.emergency_stop(), [(0x010, "0110")]),
        (lambda: bench.safe_state(), [(0x110, "0000030000000020"), (0x120, "0000010000000020"),
                                      (0x100, "4006010000000020")]),
        (lambda: bench.release_emergency_stop(), [(0x010, "0020")]),
    ]
    for action, expected in table:
        action()
        assert sorted(frames(ctrl)) == sorted((i, bytes.fromhex(h)) for i, h in expected)


def test_cyclic_sending_every_frame_at_its_due_time() -> None:
    name = f"cyc{next(_chan)}"
    clock = ManualClock(5.0)
    pc, ctrl = SimCanBus(name, clock=clock), SimCanBus(name, clock=clock)
    bench = CanBench(pc, clock=clock, timestamps="run")
    bench.emergency_stop()
    for _ in range(100):  # polled every 10 ms for 1 s
        clock.advance(0.01)
        bench.poll()
    polled = list(iter(lambda: ctrl.recv(timeout=0), None))
    cycle = {m.frame_id: m.cycle_time / 1000 for m in DB.messages}
    for ident in (0x100, 0x110, 0x120, 0x710):  # due at 5 s, one cycle later, ... up to 6 s
        stamps = [m.timestamp for m in polled if m.arbitration_id == ident]
        assert stamps == pytest.approx(5.0 + np.arange(round(1 / cycle[ident]) + 1) * cycle[ident])
    estop = [m.timestamp for m in polled if m.arbitration_id == 0x010]
    assert estop == pytest.approx(5.0 + np.arange(51) * 0.02)  # sent at once, then repeated every 20 ms
    alive = [m.data[7] >> 4 for m in polled if m.arbitration_id == 0x100]
    assert all((b - a) % 16 == 1 for a, b in zip(alive, alive[1:]))
    pc.shutdown()
    ctrl.shutdown()


def test_one_late_poll_sends_the_same_frames_at_their_due_times() -> None:
    stamps = []
    for polls in (100, 1):
        name = f"late{next(_chan)}"
        clock = ManualClock(5.0)
        pc, ctrl = SimCanBus(name, clock=clock), SimCanBus(name, clock=clock)
        bench = CanBench(pc, clock=clock, timestamps="run")
        for _ in range(polls):
            clock.advance(1.0 / polls)
            bench.poll()
        stamps.append(sorted((m.arbitration_id, round(m.timestamp, 9)) for m in iter(lambda: ctrl.recv(timeout=0), None)))
        pc.shutdown()
        ctrl.shutdown()
    assert stamps[0] == stamps[1] and len(stamps[0]) == 4 * 11


def test_interface_time_stamps_are_mapped_onto_the_run_clock() -> None:
    """Frames keep the time the interface stamped them, whatever the poll time; the offset is the fastest delivery."""
    name = f"ts{next(_chan)}"
    run_clock = ManualClock(100.0)
    pc, ctrl = SimCanBus(name), SimCanBus(name)
    bench = CanBench(pc, clock=run_clock, listen_only=True, timestamps="interface")
    epoch = 1.7e9  # the interface's own time base, 1.7e9 - 100 s ahead of the run clock
    sent = [(run_clock() + 0.01 * i) for i in range(50)]
    for t in sent:
        ctrl.send(can.Message(timestamp=t - 100.0 + epoch, arbitration_id=0x101, data=bytes(8), is_extended_id=False))
    run_clock.advance(0.6)  # polled late: the frames waited up to 0.6 s in the queue
    times = [s.t for s in bench.poll()]
    assert times == pytest.approx([t + 0.6 - 0.49 for t in sent])  # shifted by the smallest delivery delay only
    assert np.diff(times) == pytest.approx(np.full(49, 0.01), abs=1e-6)  # float64 at 1.7e9 s: 0.2 µs
    pc.shutdown()
    ctrl.shutdown()


def frames_after(bench: CanBench, bus: can.BusABC, clock: ManualClock, steps: int) -> list[tuple[int, bytes]]:
    out = []
    for _ in range(steps):
        clock.advance(0.01)
        bench.poll()
        out += frames(bus)
    return out


def test_decode_table(buses) -> None:
    pc, ctrl = buses
    bench = CanBench(pc, clock=lambda: 3.0, listen_only=True, timestamps="receive")
    table = [
        ((0x101, "b80bc201020000a0"), "drive", {"drive.speed": 1500.0, "drive.torque": 45.0, "drive.state": 2,
                                                "drive.fault_code": 0, "drive.alive": 10}),
        ((0x111, "9411800c09000050"), "clutch", {"clutch.torque": 45.0, "clutch.position": 3.2,
                                                 "clutch.clamp_state": 1, "clutch.state": 2,
                                                 "clutch.fault_code": 0, "clutch.alive": 5}),
        ((0x703, "0203"), "load", {"load.hb_state": 2, "load.hb_alive": 3}),
    ]
    for (ident, data), controller, values in table:
        ctrl.send(can.Message(arbitration_id=ident, data=bytes.fromhex(data), is_extended_id=False))
        (s,) = bench.poll()
        assert (s.controller, s.t) == (controller, 3.0)
        assert s.values == pytest.approx(values)
    assert bench.latest["clutch.position"] == pytest.approx(3.2)


def test_malformed_frames_counted_not_crashed(buses) -> None:
    pc, ctrl = buses
    bench = CanBench(pc, listen_only=True)
    for msg in [can.Message(arbitration_id=0x101, data=b"\x01\x02", is_extended_id=False),
                can.Message(arbitration_id=0x555, data=b"\x00" * 8, is_extended_id=False),
                can.Message(arbitration_id=0x101, data=b"\x00" * 8, is_extended_id=True),
                can.Message(arbitration_id=0x101, is_error_frame=True, is_extended_id=False)]:
        ctrl.send(msg)
    assert bench.poll() == []
    assert (bench.stats.bad_dlc, bench.stats.unknown_id, bench.stats.error_frames) == (1, 2, 1)
    with pytest.raises(CanConfigError):
        bench.set_drive_speed(1000)


def test_codec_matches_cantools_and_vectorised() -> None:
    rng = np.random.default_rng(1)
    db = cantools.database.Database()
    db.add_dbc_string(MOTOROLA_DBC)
    for m in list(DB.messages) + list(db.messages):
        codec = MessageCodec(m)
        rows = rng.integers(0, 256, (300, m.length), dtype=np.uint8)
        cols = codec.decode_array(rows)
        for i, row in enumerate(rows):
            expected = m.decode(bytes(row), decode_choices=False)
            assert codec.decode(bytes(row)) == pytest.approx(expected), m.name
            assert {k: c[i] for k, c in cols.items()} == pytest.approx(expected), m.name
            assert codec.encode(expected) == m.encode(expected, strict=False), m.name


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(max_size=8), st.booleans())
def test_fuzz_driver_any_frame(ident: int, data: bytes, extended: bool) -> None:
    bench = CanBench(SimCanBus(f"fz{next(_chan)}"), clock=lambda: 0.0, listen_only=True)
    sample = bench.handle(can.Message(arbitration_id=ident, data=data, is_extended_id=extended), 0.0)
    s = bench.stats
    assert (sample is not None) == (s.frames_ok == 1)
    assert s.frames_ok + s.unknown_id + s.bad_dlc + s.decode_errors == 1
    bench.close()


# -- closed loop against the emulator in simulated time --------------------------------------------------

@pytest.fixture
def loop():
    name = f"loop{next(_chan)}"
    clock = ManualClock()
    pc, ctrl = SimCanBus(name, clock=clock), SimCanBus(name, clock=clock)
    emu, bench = CanBenchEmulator(ctrl, clock=clock), CanBench(pc, clock=clock, timestamps="run")
    yield clock, emu, bench
    pc.shutdown()
    ctrl.shutdown()


def step(clock: ManualClock, emu: CanBenchEmulator, bench: CanBench, seconds: float, dt: float = 0.01) -> list:
    out = []
    for _ in range(round(seconds / dt)):
        clock.advance(dt)
        emu.poll()
        out += bench.poll()
    return out


def test_set_points_are_tracked(loop) -> None:
    clock, emu, bench = loop
    bench.set_drive_speed(1500)
    bench.set_clutch_torque(45)
    bench.set_load_torque(30)
    out = step(clock, emu, bench, 5.0)
    latest = bench.latest
    assert latest["drive.speed"] == pytest.approx(1500, abs=1) and latest["clutch.torque"] == pytest.approx(45, abs=0.1)
    assert latest["load.torque"] == pytest.approx(30, abs=0.1) and latest["load.speed"] > 0
    assert latest["drive.state"] == sig.STATE_RUNNING and latest["clutch.clamp_state"] == sig.CLAMP_SLIPPING
    assert len(out) == 3 * 500 + 3 * 50  # every status frame (10 ms) and heartbeat (100 ms) due in (0, 5] s
    assert bench.stats.alive_errors == 0 and bench.pop_events() == []
    assert emu.stats.malformed == 0


def test_silent_controller_event_and_back(loop) -> None:
    clock, emu, bench = loop
    step(clock, emu, bench, 0.5)
    emu.silence("clutch")
    step(clock, emu, bench, 0.2)
    (ev,) = bench.pop_events()
    assert (ev.controller, ev.kind) == ("clutch", "silent") and 0.05 < ev.t - 0.5 <= 0.07
    emu.silence("clutch", False)
    step(clock, emu, bench, 1.0)
    assert [(e.controller, e.kind) for e in bench.pop_events()] == [("clutch", "back")]
    assert bench.stats.alive_errors == 0  # the counter continued from where it stopped


def test_fault_code_event(loop) -> None:
    clock, emu, bench = loop
    bench.set_load_torque(100)
    step(clock, emu, bench, 0.5)
    emu.set_fault("load", 2)
    step(clock, emu, bench, 0.5)
    (ev,) = bench.pop_events()
    assert (ev.controller, ev.kind) == ("load", "fault") and bench.faulted == {"load"}
    assert bench.latest["load.fault_code"] == 2 and bench.latest["load.state"] == sig.STATE_FAULT
    assert abs(bench.latest["load.torque"]) < 1.0  # faulted controller went to its safe set-point
    emu.clear_fault("load")
    step(clock, emu, bench, 0.1)
    assert [e.kind for e in bench.pop_events()] == ["fault_cleared"]


def test_frozen_alive_counter(loop) -> None:
    clock, emu, bench = loop
    step(clock, emu, bench, 0.2)
    emu.freeze_alive("drive")
    step(clock, emu, bench, 0.1)
    assert bench.stats.alive_errors >= 9 and {e.kind for e in bench.pop_events()} == {"alive_error"}


def test_raw_garbage_on_bus(loop) -> None:
    clock, emu, bench = loop
    step(clock, emu, bench, 0.1)
    emu.send_raw(0x101, b"\x00\x01\x02")
    emu.send_raw(0x7FF, b"\x00" * 8)
    step(clock, emu, bench, 0.1)
    assert bench.stats.bad_dlc == 1 and bench.stats.unknown_id == 1 and bench.stats.alive_errors == 0


def test_command_timeout_fault(loop) -> None:
    clock, emu, bench = loop
    bench.set_drive_speed(1000)
    step(clock, emu, bench, 0.5)
    for _ in range(40):  # the PC stops sending; after 3 command cycles (0.3 s) the controller notices
        clock.advance(0.01)
        emu.poll()
    assert emu.state("drive") == (sig.STATE_FAULT, sig.FAULT_COMMAND_TIMEOUT)
    step(clock, emu, bench, 0.1)
    assert emu.state("drive") == (sig.STATE_RUNNING, 0)


def test_emergency_stop_and_safe_state(loop) -> None:
    clock, emu, bench = loop
    bench.set_drive_speed(2000)
    bench.set_clutch_torque(65)
    bench.set_load_torque(300)
    step(clock, emu, bench, 2.0)
    bench.emergency_stop()
    step(clock, emu, bench, 2.0)
    assert emu.estop and all(bench.latest[f"{c}.state"] == sig.STATE_ESTOP for c in sig.CONTROLLERS)
    assert bench.latest["clutch.torque"] < 0.5 and bench.latest["clutch.clamp_state"] == sig.CLAMP_OPEN
    bench.release_emergency_stop()
    bench.safe_state()
    step(clock, emu, bench, 3.0)
    assert not emu.estop
    assert bench.latest["drive.speed"] == pytest.approx(800, abs=5) and bench.latest["load.torque"] == pytest.approx(0)
    assert bench.latest["clutch.clamp_state"] == sig.CLAMP_OPEN


def test_from_config() -> None:
    bench = CanBench.from_config({"interface": "virtual", "channel": f"cfg{next(_chan)}"}, listen_only=True)
    assert bench.poll() == []
    bench.close()


class _DeadBus(can.BusABC):
    """A bus whose adapter is gone: every receive raises python-can's own error."""

    def __init__(self) -> None:
        super().__init__(channel="dead")

    def send(self, msg, timeout=None):
        raise can.CanOperationError("adapter gone")

    def _recv_internal(self, timeout):
        raise can.CanOperationError("adapter gone")


def test_the_can_driver_raises_its_own_errors() -> None:
    """Configuration, an unopenable bus and a failing interface are CanDriverErrors (python-can's tree as model)."""
    with pytest.raises(CanConfigError):
        CanBench(_DeadBus(), timestamps="sometimes")
    with pytest.raises(CanConfigError):
        CanBench(_DeadBus(), dbc=Path(__file__))  # not a DBC
    with pytest.raises(CanBusError):
        CanBench.from_config({"interface": "no_such_interface", "channel": "x"})
    bus = _DeadBus()
    bench = CanBench(bus, listen_only=True)
    with pytest.raises(CanBusError, match="adapter gone"):
        bench.receive()
    bus.shutdown()
