"""Bench CAN: DBC contents, exact frames, codec vs cantools, watchdog events, fault injection, safe state."""

import itertools
import zlib
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from can.io import blf
from hypothesis import given, settings
from hypothesis import strategies as st
from isal import isal_zlib

from benchlab.runner.devices import BLF_COMPRESSION, BLF_OBJECT_BYTES, BenchConfig, open_can_log
from drivers import can_signals as sig
from drivers.can_bench import CanBench
from drivers.can_codec import CodecTable, MessageCodec
from drivers.can_frames import FRAME, frames_from_messages, in_time_order, messages_from_frames
from drivers.can_log import IsalBLFWriter, log_frames
from drivers.errors import CanBusError, CanConfigError, CanLogError
from sim_bench.emulators import CanBenchEmulator, ManualClock, SimCanBus
from sim_bench.emulators.drivetrain import FirstOrderDrivetrain

DB = cantools.database.load_file(str(sig.BENCH_DBC))
_chan = itertools.count()

ODD_DBC = """VERSION ""
BS_:
BU_: A
BO_ 1100 Float: 8 A
 SG_ F : 0|32@1- (1,0) [0|0] "" A
 SG_ G : 32|16@1+ (0.5,1) [0|100] "" A
BO_ 1101 Long: 12 A
 SG_ H : 0|16@1+ (1,0) [0|60000] "" A
 SG_ K : 80|16@1- (0.1,0) [-100|100] "" A
SIG_VALTYPE_ 1100 F : 1;
"""

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


def test_frames_come_in_time_order_ties_as_they_arrived() -> None:
    """A poll's frames as given where their stamps never decrease (the same array), else stably sorted."""
    frames = np.zeros(6, FRAME)
    frames["timestamp"] = [0.1, 0.2, 0.2, 0.3, 0.3, 0.5]
    frames["arbitration_id"] = np.arange(6)
    assert in_time_order(frames) is frames
    shuffled = frames[[4, 0, 3, 2, 1, 5]]
    ordered = in_time_order(shuffled)
    assert ordered["timestamp"].tolist() == frames["timestamp"].tolist()
    assert ordered["arbitration_id"].tolist() == [0, 2, 1, 4, 3, 5]  # ties keep their order of arrival
    ties_swapped = frames[[0, 2, 1]]
    assert in_time_order(ties_swapped) is ties_swapped  # equal stamps: in order as they are


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


def test_codec_table_decodes_and_encodes_a_mixed_batch_as_each_codec_frame_by_frame() -> None:
    """One compiled pass over frames of many messages (Intel, Motorola, float fallback, 12 bytes) = per frame."""
    rng = np.random.default_rng(2)
    db = cantools.database.Database()
    db.add_dbc_string(MOTOROLA_DBC)
    db.add_dbc_string(ODD_DBC)
    codecs = [MessageCodec(m) for m in list(DB.messages) + list(db.messages)]
    table = CodecTable(codecs)
    which = rng.integers(0, len(codecs), 2000)
    payloads = np.zeros((len(which), table.payload_bytes), dtype=np.uint8)
    for i, m in enumerate(which):
        payloads[i, :codecs[m].length] = rng.integers(0, 256, codecs[m].length)
    values, valid = table.decode(which, payloads)
    assert valid.all()
    for i, m in enumerate(which):
        codec = codecs[m]
        expected = codec.decode(bytes(payloads[i, :codec.length]))
        got = {key: values[i, j] for j, key in enumerate(codec.columns) if key is not None}
        assert got.keys() == expected.keys()
        same = [got[k] == expected[k] or (np.isnan(got[k]) and np.isnan(expected[k])) for k in got]
        assert all(same), codec.message.name
    values = np.nan_to_num(values)
    vectorised = ~np.isin(which, [i for i, c in enumerate(codecs) if c.message.name in ("Float", "Long")])
    values[vectorised & (np.arange(len(which)) % 5 == 0)] *= 3.0  # some beyond their range: saturated
    encoded = table.encode(which, values)
    for i, m in enumerate(which):
        codec = codecs[m]
        assert bytes(encoded[i, :codec.length]) == codec.encode(dict(zip(codec.columns, values[i].tolist())))
        assert not encoded[i, codec.length:].any()


def _messages_of_every_kind(count: int) -> list[can.Message]:
    """Frames of every kind (standard, extended, remote, error, FD; sent and received; channels), in time order."""
    rng = np.random.default_rng(3)
    messages, t = [], 1.7e9 + 0.1234567
    for _ in range(count):
        t += rng.uniform(0, 0.003)
        kind = rng.integers(0, 20)
        kw = dict(timestamp=t, arbitration_id=int(rng.integers(0, 0x7FF)), is_extended_id=bool(rng.integers(0, 2)),
                  data=rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes(),
                  is_rx=bool(rng.integers(0, 2)), channel=[None, 0, "can1", 2][rng.integers(0, 4)])
        if kind == 0:
            kw.update(is_error_frame=True)
        elif kind == 1:
            kw.update(is_fd=True, data=rng.integers(0, 256, 12, dtype=np.uint8).tobytes(), bitrate_switch=True)
        elif kind == 2:
            kw.update(is_remote_frame=True, data=b"", dlc=4)
        messages.append(can.Message(**kw))
    return messages


def test_bulk_blf_log_is_byte_for_byte_what_python_can_writes_frame_by_frame(tmp_path) -> None:
    """Frames of every kind into a BLF file: fed as arrays, python-can's own writer produces the same file, and
    python-can reads the frames back."""
    messages = _messages_of_every_kind(3000)
    one_by_one = can.Logger(str(tmp_path / "a.blf"), max_container_size=4096)
    for msg in messages:
        one_by_one.on_message_received(msg)
    one_by_one.stop()
    in_bulk = can.Logger(str(tmp_path / "b.blf"), max_container_size=4096)
    for chunk in np.array_split(frames_from_messages(messages), 37):
        log_frames(in_bulk, chunk)
    in_bulk.stop()
    assert (tmp_path / "a.blf").read_bytes() == (tmp_path / "b.blf").read_bytes()
    back = list(can.LogReader(str(tmp_path / "b.blf")))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == [(m.arbitration_id, bytes(m.data)) for m in messages]
    assert np.allclose([m.timestamp for m in back], [m.timestamp for m in messages], rtol=0, atol=1e-6)
    assert all(a.equals(b, timestamp_delta=0, check_channel=False)
               for a, b in zip(messages, messages_from_frames(frames_from_messages(messages))))


def _blf_contents(path: Path) -> tuple[tuple, list[tuple[int, int, bytes, bytes]]]:
    """A BLF file's header fields but the file's size, and each log container's compression method, declared
    size, stored bytes and inflated bytes (read here, not by python-can's reader, which hides the containers)."""
    data = path.read_bytes()
    header = blf.FILE_HEADER_STRUCT.unpack_from(data)
    at, containers = header[1], []
    while at < len(data):
        _, _, _, size, kind = blf.OBJ_HEADER_BASE_STRUCT.unpack_from(data, at)
        assert kind == blf.LOG_CONTAINER
        method, declared = blf.LOG_CONTAINER_STRUCT.unpack_from(data, at + blf.OBJ_HEADER_BASE_STRUCT.size)
        stored = data[at + blf.OBJ_HEADER_BASE_STRUCT.size + blf.LOG_CONTAINER_STRUCT.size:at + size]
        containers.append((method, declared, stored, zlib.decompress(stored) if method == blf.ZLIB_DEFLATE else stored))
        at += size + size % 4
    return header[:10] + header[11:], containers


@pytest.mark.parametrize("level", [1, 3])
def test_the_isal_blf_log_holds_what_python_cans_writer_writes_only_deflated_by_isal(tmp_path, level) -> None:
    """The bench's BLF writer (frames in bulk and frame by frame) against python-can's (frame by frame) at the
    same level: the same header, the same containers inflated, each deflated by ISA-L at that level; python-can's
    BLFReader reads the same messages back (time stamps, ids, data, flags, channels)."""
    messages = _messages_of_every_kind(3000)
    theirs = can.BLFWriter(tmp_path / "zlib.blf", max_container_size=4096, compression_level=level)
    for msg in messages:
        theirs.on_message_received(msg)
    theirs.stop()
    in_bulk = IsalBLFWriter(tmp_path / "bulk.blf", max_container_size=4096, compression_level=level)
    for chunk in np.array_split(frames_from_messages(messages), 37):
        log_frames(in_bulk, chunk)
    in_bulk.stop()
    one_by_one = IsalBLFWriter(tmp_path / "single.blf", max_container_size=4096, compression_level=level)
    for msg in messages:
        one_by_one.on_message_received(msg)
    one_by_one.stop()
    head, containers = _blf_contents(tmp_path / "zlib.blf")
    assert len(containers) > 30 and all(c[0] == blf.ZLIB_DEFLATE for c in containers)
    expected = [(blf.ZLIB_DEFLATE, declared, isal_zlib.compress(inflated, level), inflated)
                for _, declared, _, inflated in containers]
    assert [c[2] for c in expected] != [c[2] for c in containers]  # zlib's and ISA-L's streams differ
    read = list(can.BLFReader(tmp_path / "zlib.blf"))
    assert len(read) == len(messages)
    for name in ("bulk.blf", "single.blf"):
        assert _blf_contents(tmp_path / name) == (head, expected)
        assert all(a.equals(b, timestamp_delta=0) for a, b in zip(can.BLFReader(tmp_path / name), read, strict=True))


def test_the_isal_blf_log_at_level_0_is_python_cans_uncompressed_log(tmp_path) -> None:
    """compression_level 0 keeps python-can's meaning (containers stored, not ISA-L's level 0): the very file."""
    messages = _messages_of_every_kind(500)
    for name, writer in (("zlib.blf", can.BLFWriter), ("isal.blf", IsalBLFWriter)):
        log = writer(tmp_path / name, max_container_size=4096, compression_level=0)
        log_frames(log, frames_from_messages(messages))
        log.stop()
    _, containers = _blf_contents(tmp_path / "isal.blf")
    assert len(containers) > 5 and all(c[0] == blf.NO_COMPRESSION for c in containers)
    assert (tmp_path / "isal.blf").read_bytes() == (tmp_path / "zlib.blf").read_bytes()


@pytest.mark.parametrize("level", [-1, 4, 9])
def test_a_blf_compression_level_isal_lacks_is_refused_before_the_file_is_made(tmp_path, level) -> None:
    """ISA-L has levels 0 to 3 (0 stays python-can's "stored"): any other is one line, and no file."""
    with pytest.raises(ValueError, match=f"^BLF compression_level {level}: 0 \\(uncompressed\\) to 3"):
        IsalBLFWriter(tmp_path / "x.blf", compression_level=level)
    assert not (tmp_path / "x.blf").exists()


def test_the_bench_logs_blf_through_the_isal_writer_and_asc_through_python_cans(tmp_path) -> None:
    """open_can_log: a .blf log is an IsalBLFWriter at BLF_COMPRESSION, containers of about one second of the DBC's
    frames; an .asc log python-can's writer; a log that cannot be created one CanLogError line."""
    config = BenchConfig(instrument_url="sim://dmm", node_url="sim://node", can={})
    frames_per_s = sum(1000.0 / m.cycle_time for m in DB.messages if m.cycle_time)
    log = open_can_log(tmp_path / "run.blf", config)
    log.stop()
    assert type(log) is IsalBLFWriter and log.compression_level == BLF_COMPRESSION
    assert log.max_container_size == int(frames_per_s * BLF_OBJECT_BYTES) > 4096
    log = open_can_log(tmp_path / "run.asc", config)
    log.stop()
    assert type(log) is can.ASCWriter
    with pytest.raises(CanLogError, match=r"^\S*nowhere.run.blf: cannot be written \(No such file or directory\)$"):
        open_can_log(tmp_path / "nowhere" / "run.blf", config)


class _FrameByFrame(can.BusABC):
    """Only python-can's per-frame API of another bus (as a hardware interface offers): no bulk read."""

    def __init__(self, bus: can.BusABC) -> None:
        super().__init__(channel=None)
        self._bus = bus

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._bus.send(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self._bus.recv(timeout=0), False

    def shutdown(self) -> None:
        self._bus.shutdown()
        super().shutdown()


def test_driver_gives_the_same_results_frame_by_frame_as_in_bulk(tmp_path) -> None:
    """The simulated bus hands the driver all waiting frames as one array; a hardware interface goes through
    python-can's recv() one frame at a time. The same traffic (faults, silence, frozen counters, garbage,
    emergency stop) gives the same samples, counters, events, latest values and CAN log either way."""
    results = []
    for per_frame in (False, True):
        name = f"same{next(_chan)}"
        clock = ManualClock(2.0)
        pc, ctrl = SimCanBus(name, clock=clock), SimCanBus(name, clock=clock)
        emu = CanBenchEmulator(ctrl, clock=clock)
        log = can.Logger(str(tmp_path / f"{per_frame}.blf"))
        bench = CanBench(_FrameByFrame(pc) if per_frame else pc, clock=clock, timestamps="run", log=log)
        samples, events = [], []

        def run(seconds: float, dt: float) -> None:
            for _ in range(round(seconds / dt)):
                clock.advance(dt)
                bench.send_due()
                emu.poll()
                samples.extend((s.t, s.controller, s.message, s.values) for s in bench.receive())
                events.extend(bench.pop_events())

        bench.set_drive_speed(1500)
        bench.set_clutch_torque(45)
        bench.set_load_torque(30)
        run(1.0, 0.05)
        run(2.0, 0.5)
        emu.silence("clutch")
        run(0.3, 0.03)
        emu.silence("clutch", False)
        emu.set_fault("load", 3)
        run(0.5, 0.05)
        emu.clear_fault("load")
        emu.freeze_alive("drive")
        run(0.2, 0.01)
        emu.freeze_alive("drive", False)
        emu.send_raw(0x101, b"\x00\x01")
        emu.send_raw(0x7FF, bytes(8))
        emu.send_raw(0x101, bytes(8), is_extended_id=True)
        emu.send_raw(0x010, b"\x31\x00")  # another node's emergency stop (source 3) on the bus
        bench.emergency_stop()
        run(0.5, 0.05)
        bench.release_emergency_stop()
        run(0.5, 0.1)
        bench.close()
        ctrl.shutdown()
        results.append((samples, events, bench.stats, dict(bench.latest), bench.faulted, bench.silent))
    bulk, per_frame = results
    assert len(bulk[0]) > 1000 and {e.kind for e in bulk[1]} >= {"silent", "back", "fault", "alive_error", "estop"}
    assert (bulk[2].unknown_id, bulk[2].bad_dlc) == (2, 1)  # 0x7FF and the extended 0x101; 0x101 of 2 bytes
    assert bulk == per_frame
    assert (tmp_path / "False.blf").read_bytes()[144:] == (tmp_path / "True.blf").read_bytes()[144:]  # header: sizes


@pytest.mark.parametrize("writer", [can.BLFWriter, IsalBLFWriter])
def test_a_can_log_that_cannot_be_written_stops_with_can_log_error(tmp_path, loop, writer) -> None:
    """The bulk write into a BLF file that fails (here: its file closed under it, as a full disk fails a write)
    is one CanLogError, and the log is given up, not written half."""
    clock, emu, bench = loop
    bench.log = writer(tmp_path / "run.blf", max_container_size=4096)
    step(clock, emu, bench, 0.5)
    bench.log.file.close()
    with pytest.raises(CanLogError, match="CAN log cannot be written: ValueError: .*run.blf: closed, frames cannot be"):
        step(clock, emu, bench, 1.0)
    assert bench.log is None


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


class _RecordingDrivetrain(FirstOrderDrivetrain):
    """The default physics, recording the time each drive set-point took effect (the emulator's last advance)."""

    def __init__(self, t0: float) -> None:
        super().__init__(t0=t0)
        self.drive: list[tuple[float, float]] = []

    def set_drive_speed(self, rpm: float) -> None:
        super().set_drive_speed(rpm)
        self.drive.append((self.t, rpm))


def test_command_timeout_applies_the_safe_setpoints_at_the_deadline() -> None:
    """Issue 29: a controller that times out holds its safe set-points from the very instant it reports the fault."""
    name, clock = f"deadline{next(_chan)}", ManualClock()
    pc, ctrl = SimCanBus(name, clock=clock), SimCanBus(name, clock=clock)
    physics = _RecordingDrivetrain(clock())
    emu, bench = CanBenchEmulator(ctrl, physics, clock=clock), CanBench(pc, clock=clock, timestamps="run")
    bench.set_drive_speed(1000)
    bench.set_clutch_torque(60)
    bench.set_load_torque(200)
    step(clock, emu, bench, 0.5)
    assert physics.speed_sp == 1000 and not physics.open_request
    t_stop = clock()
    for _ in range(60):  # the PC stops sending (a host stall); the emulator alone runs on
        clock.advance(0.01)
        emu.poll()
    low, high = t_stop - 0.2, clock()  # the deadline, from the state the controller reports
    assert emu.state("drive", low)[0] == sig.STATE_RUNNING and emu.state("drive", high)[0] == sig.STATE_FAULT
    for _ in range(60):
        mid = (low + high) / 2
        low, high = (low, mid) if emu.state("drive", mid)[0] == sig.STATE_FAULT else (mid, high)
    t_safe, rpm = physics.drive[-1]
    assert rpm == 0.0 and t_safe == pytest.approx(high, abs=1e-9)  # at the boundary, not merely some time past it
    assert physics.open_request and physics.clutch_sp == 0.0 and physics.load_sp == 0.0
    pc.shutdown()
    ctrl.shutdown()


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


def test_emergency_stop_on_a_dbc_without_one_is_refused_and_changes_no_other_schedule() -> None:
    """A mapping without the emergency-stop message: asking for one raises, and the cyclic frames the PC does send
    keep their schedule, frame for frame, as on a twin bench that was never asked (the stop's slot is looked up,
    never taken as a default)."""
    signals = {key: where for key, where in sig.BENCH_SIGNALS.items() if not key.startswith("estop.")}
    received = []
    for asked in (True, False):
        channel = f"noestop{next(_chan)}"
        clock, listener = ManualClock(), can.Bus(interface="virtual", channel=channel)
        bench = CanBench(can.Bus(interface="virtual", channel=channel), signals=signals, clock=clock,
                         timestamps="run")
        try:
            clock.advance(1.05)  # between two cycles: a schedule started anew here would fall due at other times
            if asked:
                with pytest.raises(KeyError):
                    bench.emergency_stop()
            clock.advance(1.0)
            bench.send_due()
            received.append([m.arbitration_id for m in iter(lambda: listener.recv(0), None)])
        finally:
            bench.close()
            listener.shutdown()
    assert received[0] and received[0] == received[1]
