"""ClutchSensorNode frame + gateway: documented example, byte tables, corruption, sequence gaps, drop-outs, fuzzing."""

import itertools
import math
import random
from contextlib import nullcontext

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import cobs, node_frame
from drivers.clutch_node import ClutchNodeGateway
from drivers.errors import ConnectionLost, DriverConfigError, DriverError, FrameError
from drivers.node_frame import NodeFrame
from sim_bench.emulators import ClutchNodeEmulator, ConstantNodeInputs, ManualClock, NodeInputs, ScriptedSerial, registry

EXAMPLE = NodeFrame(seq=0x1234, node_time_ms=123456, r_mohm=(1385055, 1097347), supply_mv=5012, rssi_dbm=-67, lqi=208)
EXAMPLE_WIRE = bytes.fromhex("02 01 06 34 12 40 e2 01 04 5f 22 15 04 83 be 10 07 94 13 bd d0 ad f7 00")


def frame(seq: int, t_ms: int | None = None, r=(1097347, 1385055), flags: int = 0) -> NodeFrame:
    return NodeFrame(seq & 0xFFFF, (seq * 50 if t_ms is None else t_ms) & 0xFFFFFFFF, r, 5000, -60, 200, flags)


def gateway(period_s: float = 0.05, clock=None) -> ClutchNodeGateway:
    return ClutchNodeGateway(None, period_s=period_s, clock=clock or ManualClock())


def test_crc_check_value() -> None:
    assert node_frame.crc16(b"123456789") == 0x29B1


def test_documented_example() -> None:
    assert node_frame.encode(EXAMPLE) == EXAMPLE_WIRE
    assert node_frame.decode(EXAMPLE_WIRE[:-1]) == EXAMPLE


@settings(max_examples=300, deadline=None)
@given(st.lists(st.builds(NodeFrame, st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF),
                          st.tuples(st.integers(0, 0xFFFFFFFF), st.integers(0, 0xFFFFFFFF)), st.integers(0, 0xFFFF),
                          st.integers(-128, 127), st.integers(0, 255), st.integers(0, 255)), max_size=5))
def test_bulk_encode_and_decode_are_frame_by_frame(frames: list[NodeFrame]) -> None:
    """The compiled bulk encoder (the node emulator's) writes the same bytes as `encode`, zeros and extremes included,
    and the bulk decoder (the gateway's) reads back the same fields as `decode`."""
    rows = np.array([rows_of(f) for f in frames], dtype=np.int64).reshape(-1, len(node_frame.FIELDS))
    wire = node_frame.encode_rows(rows)
    assert wire == b"".join(node_frame.encode(f) for f in frames)
    assert node_frame.encode_rows(np.array([rows_of(EXAMPLE)])) == EXAMPLE_WIRE
    decoded, status, rest = node_frame.decode_stream(wire + b"\x03\x01")
    assert np.array_equal(decoded, rows) and list(status) == [node_frame.OK] * len(frames) and rest == b"\x03\x01"
    assert [node_frame.frame_of(r) for r in decoded.tolist()] == [node_frame.decode(c) for c in wire.split(b"\0")[:-1]]


def rows_of(f: NodeFrame) -> tuple[int, ...]:
    return (f.version, f.flags, f.seq, f.node_time_ms, f.r_mohm[0], f.r_mohm[1], f.supply_mv, f.rssi_dbm, f.lqi)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(min_size=0, max_size=30).map(lambda b: b.replace(b"\0", b"\x01")), max_size=6),
       st.sampled_from([b"", node_frame.encode(EXAMPLE)[:-1]]))
def test_bulk_decode_status_is_decode_outcome(chunks: list[bytes], valid: bytes) -> None:
    """Each chunk's status from the bulk decoder is what `decode` makes of it: a frame, a CRC error or malformed."""
    chunks = chunks + [valid, bytes([valid[0] ^ 1]) + valid[1:] if valid else b""]
    _, status, _ = node_frame.decode_stream(b"".join(c + b"\0" for c in chunks))
    for chunk, code in zip(chunks, status.tolist()):
        try:
            node_frame.decode(chunk)
            outcome = node_frame.OK
        except node_frame.CrcMismatch:
            outcome = node_frame.BAD_CRC
        except node_frame.MalformedFrame:
            outcome = "malformed"
        assert outcome == (code if code in (node_frame.OK, node_frame.BAD_CRC) else "malformed"), (chunk, code)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_cobs_round_trip(data: bytes) -> None:
    enc = cobs.encode(data)
    assert 0 not in enc and cobs.decode(enc) == data


def test_byte_table_through_serial() -> None:
    port = ScriptedSerial([(b"", b"\x13\x37\x00" + EXAMPLE_WIRE), (b"", node_frame.encode(frame(0x1235, 123506))[:10])])
    g = ClutchNodeGateway(port, clock=lambda: 7.0)
    (s,) = g.poll()
    assert (s.seq, s.node_time_ms, s.t_host, s.supply_mv, s.rssi_dbm, s.lqi) == (0x1234, 123456, 7.0, 5012, -67, 208)
    assert s.resistance_ohm == (1385.055, 1097.347) and s.temperature_c[0] == pytest.approx(100.0, abs=1e-9)
    assert s.sensor_status == ("ok", "ok") and g.stats.resyncs == 1 and g.stats.frames_ok == 1
    port.deliver(node_frame.encode(frame(0x1235, 123506))[10:])
    assert [x.seq for x in g.poll()] == [0x1235] and g.stats.lost == 0


def test_sensor_status_from_flags_and_values() -> None:
    g = gateway()
    nv = node_frame.NO_VALUE
    cases = [((nv, nv), node_frame.CH1_OPEN | node_frame.CH2_SHORT, ("open", "short")),
             ((1000000, nv), 0, ("ok", "fault")),
             ((1000000, 1000000), node_frame.ADC_FAULT, ("fault", "fault")),
             ((100000, 5000000), 0, ("short", "range"))]
    for i, (r, flags, status) in enumerate(cases):
        (s,) = g.feed(node_frame.encode(frame(i, r=r, flags=flags)))
        assert s.sensor_status == status
        for st_, ohm, deg in zip(status, s.resistance_ohm, s.temperature_c):
            assert (deg is None) == (st_ != "ok")
            assert (ohm is None) == (st_ not in ("ok", "range"))


def test_sequence_gap_and_wrap() -> None:
    g = gateway()
    seqs = [65533, 65534, 65535, 0, 1, 4]  # wraps cleanly, then loses 2 and 3
    out = g.feed(b"".join(node_frame.encode(frame(s, t_ms=(i if s != 4 else 6) * 50)) for i, s in enumerate(seqs)))
    assert [s.seq for s in out] == seqs and g.stats.lost == 2 and g.stats.dropouts == 0


def test_multiple_wraps_use_node_clock() -> None:
    g = gateway(period_s=0.01)
    g.feed(node_frame.encode(frame(10, t_ms=0)))
    g.feed(node_frame.encode(frame(20, t_ms=(65536 + 10) * 10)))  # one full wrap plus 10 frames
    assert g.stats.lost == 65536 + 9
    start, end = g.pop_events()  # the gap arrived in one piece: its start is reported with its end
    assert start.kind == "dropout_start" and start.last_seq == 10
    assert end.kind == "dropout_end" and end.span_s == pytest.approx(655.46) and end.lost_frames == 65545


def test_duplicate_dropped() -> None:
    g = gateway()
    out = g.feed(node_frame.encode(frame(5)) * 2)
    assert len(out) == 1 and g.stats.duplicates == 1 and g.stats.lost == 0


def test_exhaustive_single_byte_corruption_never_yields_a_reading() -> None:
    """Every position × every replacement byte of the example frame: either dropped or (if unchanged) identical."""
    before, after = node_frame.encode(frame(1)), node_frame.encode(frame(3))
    for pos, value in itertools.product(range(len(EXAMPLE_WIRE)), range(256)):
        if EXAMPLE_WIRE[pos] == value:
            continue
        g = gateway()
        bad = EXAMPLE_WIRE[:pos] + bytes([value]) + EXAMPLE_WIRE[pos + 1:]
        seqs = [s.seq for s in g.feed(before + bad + after)]
        delimiter_hit = pos == len(EXAMPLE_WIRE) - 1  # the damaged frame swallows the next one
        assert seqs == ([1] if delimiter_hit else [1, 3]), (pos, value)
        assert g.stats.crc_errors + g.stats.malformed >= 1, (pos, value)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_fuzz_any_bytes(data: bytes) -> None:
    g = gateway()
    for s in g.feed(data):  # whatever comes out passed the CRC: internally consistent
        assert len(s.resistance_ohm) == 2
    assert g.stats.frames_ok <= data.count(0)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_fuzz_corrupted_stream_never_invents(data) -> None:
    frames = [frame(i, r=(1000000 + i, 1100000 + i)) for i in range(4)]
    wire = bytearray(b"".join(node_frame.encode(f) for f in frames))
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(wire) - 1))
        op = data.draw(st.sampled_from(["replace", "delete", "insert"]))
        if op == "replace":
            wire[pos] = data.draw(st.integers(0, 255))
        elif op == "delete":
            del wire[pos]
        else:
            wire.insert(pos, data.draw(st.integers(0, 255)))
    g = gateway()
    split = data.draw(st.integers(0, len(wire)))
    out = g.feed(bytes(wire[:split])) + g.feed(bytes(wire[split:]))
    originals = {(f.seq, f.r_mohm) for f in frames}
    for s in out:
        assert (s.seq, tuple(round(r * 1000) for r in s.resistance_ohm)) in originals


def test_garbage_resync_and_overlong_run() -> None:
    g = gateway()
    assert g.feed(b"\x01\x02\x03" * 100) == [] and g.stats.resyncs == 1  # over-long run: buffer dropped
    out = g.feed(b"\x04\x05\x00" + node_frame.encode(frame(1)) + b"\xaa" * 5 + node_frame.encode(frame(2)))
    assert [s.seq for s in out] == [1] and g.stats.resyncs == 2 and g.stats.malformed == 1
    assert [s.seq for s in g.feed(node_frame.encode(frame(3)))] == [3] and g.stats.lost == 1


# -- emulator + faults -----------------------------------------------------------------------------------------

@pytest.fixture
def bench():
    clock = ManualClock(100.0)
    emu = ClutchNodeEmulator(clock=clock, period_s=0.05)
    registry.register("node-test", emu)
    g = ClutchNodeGateway.open("sim://node-test", period_s=0.05, clock=clock)
    yield clock, emu, g
    registry.unregister("node-test")


def run(clock: ManualClock, g: ClutchNodeGateway, seconds: float, step: float = 0.01) -> list:
    out = []
    for _ in range(round(seconds / step)):
        clock.advance(step)
        out += g.poll()
    return out


def test_emulator_clean_stream(bench) -> None:
    clock, emu, g = bench
    out = run(clock, g, 10.0)
    assert len(out) == emu.frames_sent == 201 and out[0].flags & node_frame.NODE_RESET
    assert [s.seq for s in out] == list(range(201))
    assert g.stats.frames_ok == 201 and g.stats.lost == g.stats.dropouts == 0 and g.pop_events() == []


def test_emulator_temperatures_through_provider(bench) -> None:
    from drivers import cvd
    clock, emu, g = bench
    emu.provider = ConstantNodeInputs(NodeInputs((float(cvd.resistance(80.0)), math.inf), supply_mv=3000))
    s = run(clock, g, 0.1)[-1]
    assert s.temperature_c[0] == pytest.approx(80.0, abs=1e-3) and s.sensor_status == ("ok", "open")
    assert s.flags & node_frame.LOW_SUPPLY and s.flags & node_frame.CH2_OPEN


def test_radio_silence_is_a_gap(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 1.0)
    emu.radio_silence(2.0)
    run(clock, g, 0.5)
    (start,) = g.pop_events()
    assert start.kind == "dropout_start" and start.last_seq == 20
    out = run(clock, g, 3.0)
    (end,) = g.pop_events()
    assert end.kind == "dropout_end" and end.span_s == pytest.approx(2.05) and end.lost_frames == 40
    assert g.stats.lost == emu.frames_suppressed == 40 and g.stats.dropouts == 1
    assert g.stats.frames_ok == emu.frames_sent  # nothing lost beyond the silence itself
    assert out[0].seq == 61


def test_short_silence_counts_lost_without_dropout(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 1.0)
    emu.radio_silence(0.1)
    run(clock, g, 1.0)
    assert g.stats.lost == 2 and g.stats.dropouts == 0 and g.pop_events() == []


def test_power_loss_reboots_node(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 1.0)
    emu.power_loss(3.0)
    out = run(clock, g, 4.0)
    kinds = [e.kind for e in g.pop_events()]
    assert kinds == ["dropout_start", "node_reset", "dropout_end"]
    assert g.stats.node_resets == 1 and g.stats.dropouts == 1
    assert out[0].seq == 0 and out[0].flags & node_frame.NODE_RESET and g.stats.frames_ok == emu.frames_sent


@pytest.mark.parametrize("how, counter", [("flip", "crc_errors"), ("truncate", "malformed"), ("garbage", "malformed")])
def test_corrupted_frames_counted(bench, how: str, counter: str) -> None:
    clock, emu, g = bench
    run(clock, g, 1.0)
    emu.corrupt_next(how, count=3)
    run(clock, g, 1.0)
    assert getattr(g.stats, counter) == 3 and g.stats.lost == 3
    assert g.stats.frames_ok == emu.frames_sent - 3 and g.stats.dropouts == 0


def test_injected_noise_bytes(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 0.5)
    emu.inject_bytes(b"\x00\x07garbage\x00")
    run(clock, g, 0.5)
    assert g.stats.malformed == 1 and g.stats.lost == 0 and g.stats.frames_ok == emu.frames_sent


def test_disconnect_and_reconnect(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 0.5)
    emu.connected = False
    with pytest.raises(ConnectionLost):
        run(clock, g, 0.1)
    emu.connected = True
    g.reconnect()
    run(clock, g, 0.5)
    assert g.stats.frames_ok == emu.frames_sent and g.stats.lost == 0


def test_dropout_between_two_polls_reports_start_and_end(bench) -> None:
    """Polled every 1 s (the simulated bench's slow tick), a 0.6 s silence is never seen as silence at a
    poll; the frames around it show it. It used to give a `dropout_end` without a `dropout_start`."""
    clock, emu, g = bench
    run(clock, g, 1.21)
    emu.radio_silence(0.6)  # frames 101.25 … 101.80 s lost
    out = run(clock, g, 2.0, step=1.0)
    start, end = g.pop_events()
    assert (start.kind, end.kind) == ("dropout_start", "dropout_end") and start.last_seq == end.last_seq == 24
    assert start.t_host == pytest.approx(101.81) and end.t_host == pytest.approx(102.21)  # dated when it began
    assert end.span_s == pytest.approx(0.65) and end.lost_frames == 12
    assert g.stats.dropouts == 1 and g.stats.lost == emu.frames_suppressed == 12 and out[0].seq == 37


def test_corrupt_frames_are_one_event_per_second(bench) -> None:
    clock, emu, g = bench
    run(clock, g, 1.0)
    for how in ["flip"] * 30 + ["truncate"] * 10:  # every other frame for 4 s, polled every 10 ms
        emu.corrupt_next(how)
        run(clock, g, 0.1)
    events = g.pop_events()
    assert len(events) == 3 and all(b.t_host - a.t_host >= 1.0 for a, b in zip(events, events[1:]))
    g.close()
    events += g.pop_events()  # close() reports the window still running
    assert {e.kind for e in events} == {"frame_errors"} and len(events) == 4
    assert sum(e.crc_errors for e in events) == g.stats.crc_errors == 30
    assert sum(e.malformed for e in events) == g.stats.malformed == 10
    assert sum(e.lost_frames for e in events) == 40 and all(e.span_s < 1.0 + 0.011 for e in events)


def _random_faults(rng: random.Random, clock: ManualClock, emu: ClutchNodeEmulator) -> None:
    """One fault of the radio link or the node, as the bench meets them."""
    fault = rng.choice(["silence", "silence", "silence", "corrupt", "corrupt", "noise", "restart", "power"])
    if fault == "silence":
        emu.radio_silence(rng.choice([rng.uniform(0.05, 0.3), rng.uniform(0.2, 1.2), rng.expovariate(1 / 2.0)]))
    elif fault == "corrupt":
        emu.corrupt_next(rng.choice(["flip", "truncate", "garbage"]), count=rng.randint(1, 30))
    elif fault == "noise":
        emu.inject_bytes(rng.randbytes(rng.randint(1, 300)))
    elif fault == "restart":
        emu.restart()
    else:
        emu.power_loss(rng.uniform(0.1, 3.0))


@pytest.mark.parametrize("seed", [1, 2])
def test_long_faulty_stream_dropouts_pair_up(bench, seed: int) -> None:
    """An hour of random drop-outs, corruptions, noise, reboots and unplugged ports, polled at random
    intervals (10 ms to 1.2 s): every dropout_end follows exactly one dropout_start, and the per-second
    frame_errors events add up to the gateway's counters."""
    clock, emu, g = bench
    rng = random.Random(seed)
    events, next_fault, unplugged_until = [], clock() + 5.0, -math.inf
    while clock() < 100.0 + 3600.0:
        clock.advance(rng.choice([0.01, 0.05, 0.1, 0.2, rng.uniform(0.01, 1.2)]))
        if clock() >= next_fault:
            if rng.random() < 0.05:
                emu.connected, unplugged_until = False, clock() + rng.uniform(0.1, 5.0)
            else:
                _random_faults(rng, clock, emu)
            next_fault = clock() + rng.expovariate(1 / 8.0)
        if not emu.connected and clock() >= unplugged_until:
            emu.connected = True
        try:
            g.poll()
        except ConnectionLost:  # what the runner does: reconnect, which fails while the cable is out
            try:
                g.reconnect()
            except ConnectionLost:
                pass
        events += g.pop_events()
    errors = [e for e in events if e.kind == "frame_errors"]
    assert all(b.t_host - a.t_host >= 1.0 for a, b in zip(errors, errors[1:]))
    g.close()
    events += g.pop_events()
    in_dropout, starts, ends = False, 0, 0
    for e in events:
        if e.kind == "dropout_start":
            assert not in_dropout, e
            in_dropout, starts = True, starts + 1
        elif e.kind == "dropout_end":
            assert in_dropout, e
            in_dropout, ends = False, ends + 1
    assert starts == g.stats.dropouts and ends in (starts, starts - 1) and starts >= 100
    errors = [e for e in events if e.kind == "frame_errors"]
    for counter in ("crc_errors", "malformed", "resyncs"):
        assert sum(getattr(e, counter) for e in errors) == getattr(g.stats, counter)
    assert 0 < len(errors) < g.stats.crc_errors + g.stats.malformed


def test_public_failures_are_driver_errors(bench) -> None:
    """Each way the gateway fails raises its own DriverError subclass, never a bare OSError or AssertionError."""
    clock, emu, g = bench
    port_that_will_not_close = ScriptedSerial([], close_error=OSError(5, "Input/output error"))
    cases = [
        (ClutchNodeGateway.open, ("nonsense://x",), ConnectionLost, False),
        (gateway().poll, (), DriverConfigError, False),
        (gateway().reconnect, (), DriverConfigError, False),
        (g.poll, (), ConnectionLost, True),
        (g.reconnect, (), ConnectionLost, True),
        (ClutchNodeGateway(port_that_will_not_close, clock=clock).close, (), ConnectionLost, False),
    ]
    for action, args, expected, unplug in cases:
        with pytest.raises(DriverError) as exc, registry.unplugged(emu) if unplug else nullcontext():
            action(*args)
        assert type(exc.value) is expected, (action, exc.value)


def test_frame_and_cobs_errors_are_driver_errors() -> None:
    for bad in (b"", b"\x05\x01", EXAMPLE_WIRE[:-2] + b"\x01", EXAMPLE_WIRE[:5] + b"\x77" + EXAMPLE_WIRE[6:-1]):
        with pytest.raises(FrameError):
            node_frame.decode(bad)
    with pytest.raises(cobs.CobsError) as exc:
        cobs.decode(b"\x05\x01")
    assert isinstance(exc.value, FrameError) and isinstance(exc.value, DriverError)


def test_real_time_read_from_default_emulator() -> None:
    import sim_bench.emulators  # noqa: F401
    g = ClutchNodeGateway.open("sim://node", period_s=0.05)
    # read() returns what arrived once it holds at least 2 (more if a loaded machine polled late); the long
    # time-out covers a first compile (numba) on a fresh clone
    assert len(g.read(2, timeout_s=30.0)) >= 2
