"""PT1000 scanner: byte-level SCPI tables, fault statuses, error policy, emulator faults, reply-parser fuzzing."""

import math
from contextlib import nullcontext

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import cvd, scpi
from drivers.errors import ConnectionLost, DeviceTimeout, DriverConfigError, DriverError, InstrumentError
from drivers.pt1000 import Pt1000Scanner
from sim_bench.emulators import (ConstantResistances, ManualClock, ScpiInstrumentEmulator, ScriptedSerial,
                                 TemperatureResistances, registry)

NO_ERR = (b"SYST:ERR?\n", b'+0,"No error"\n')


def scanner(script: list[tuple[bytes, bytes]], channels=(101, 102, 103, 104), **kw) -> tuple[Pt1000Scanner, ScriptedSerial]:
    port = ScriptedSerial(script)
    return Pt1000Scanner(port, channels, clock=lambda: 12.5, **kw), port


def test_identify_table() -> None:
    s, port = scanner([(b"*IDN?\n", b"Keysight Technologies,34972A,MY123,1.17-1.12-02-02\n")])
    assert s.identify() == "Keysight Technologies,34972A,MY123,1.17-1.12-02-02"
    assert port.finished


def test_reset_fres_table() -> None:
    s, port = scanner([(b"*RST\n", b""), (b"*CLS\n", b""), NO_ERR,
                       (b"CONF:FRES (@101:104)\n", b""), (b"ROUT:SCAN (@101:104)\n", b""), NO_ERR])
    s.reset()
    assert port.finished


def test_configure_frtd_table() -> None:
    s, port = scanner([(b"CONF:TEMP FRTD,85,(@101,103)\n", b""), (b"TEMP:TRAN:FRTD:RES:REF 1000,(@101,103)\n", b""),
                       (b"UNIT:TEMP C,(@101,103)\n", b""), (b"ROUT:SCAN (@101,103)\n", b""), NO_ERR],
                      channels=(103, 101), mode="frtd")
    s.configure()
    assert port.finished


def test_read_statuses_table() -> None:
    s, port = scanner([(b"READ?\n", b"+1.09734700E+03,+9.90000000E+37,+1.00000000E+02,+5.00000000E+03\n"), NO_ERR])
    r101, r102, r103, r104 = s.read()
    assert (r101.channel, r101.status, r101.t_host) == (101, "ok", 12.5)
    assert r101.resistance_ohm == pytest.approx(1097.347) and r101.temperature_c == pytest.approx(25.0, abs=1e-3)
    assert (r102.status, r102.resistance_ohm, r102.temperature_c) == ("open", None, None)
    assert (r103.status, r103.resistance_ohm, r103.temperature_c) == ("short", None, None)
    assert (r104.status, r104.resistance_ohm, r104.temperature_c) == ("range", 5000.0, None)
    assert port.finished


def test_frtd_read_table() -> None:
    s, _ = scanner([(b"READ?\n", b"+2.50000000E+01,+9.90000000E+37\n"), NO_ERR], channels=(101, 102), mode="frtd")
    a, b = s.read()
    assert a.status == "ok" and a.temperature_c == 25.0 and a.resistance_ohm == pytest.approx(1097.35, abs=0.01)
    assert b.status == "open" and b.temperature_c is None


def test_per_channel_coefficients() -> None:
    coef = cvd.CvdCoefficients(r0=1001.0)
    s, _ = scanner([(b"READ?\n", b"+1.00100000E+03,+1.00100000E+03\n"), NO_ERR], channels=(101, 102),
                   coefficients={102: coef})
    a, b = s.read()
    assert a.temperature_c == pytest.approx(0.256, abs=1e-3) and b.temperature_c == pytest.approx(0.0, abs=1e-9)


def test_errors_during_scan_are_recorded_not_raised() -> None:
    s, port = scanner([(b"READ?\n", b"+1.00000000E+03\n"), (b"SYST:ERR?\n", b'-222,"Data out of range"\n'), NO_ERR],
                      channels=(101,))
    (r,) = s.read()
    assert r.status == "ok" and r.temperature_c == pytest.approx(0.0)
    assert [(e.t_host, e.code, e.text) for e in s.error_log] == [(12.5, -222, "Data out of range")]
    assert port.finished


def test_configuration_error_raises() -> None:
    s, _ = scanner([(b"CONF:FRES (@101)\n", b""), (b"ROUT:SCAN (@101)\n", b""),
                    (b"SYST:ERR?\n", b'-221,"Settings conflict"\n'), NO_ERR], channels=(101,))
    with pytest.raises(InstrumentError) as exc:
        s.configure()
    assert exc.value.entries == ((-221, "Settings conflict"),)


def test_malformed_reply_raises_with_queue() -> None:
    s, _ = scanner([(b"READ?\n", b"+1.0E+03,garbage\n"), (b"SYST:ERR?\n", b'-410,"Query INTERRUPTED"\n'), NO_ERR],
                   channels=(101, 102))
    with pytest.raises(InstrumentError) as exc:
        s.read()
    assert exc.value.entries == ((-410, "Query INTERRUPTED"),)


def test_no_reply_is_timeout() -> None:
    s, _ = scanner([(b"READ?\n", b"+1.0E+03")], channels=(101,))
    with pytest.raises(DeviceTimeout):
        s.read()


def test_channel_lists() -> None:
    assert scpi.channel_list([104, 101, 102, 103, 106, 201]) == "(@101:104,106,201)"
    assert scpi.parse_channel_list("(@101:103, 106)") == [101, 102, 103, 106]
    for bad in ("101", "(@103:101)", "(@a)"):
        with pytest.raises(ValueError):
            scpi.parse_channel_list(bad)


def test_channel_list_size_is_checked_before_expanding() -> None:
    assert scpi.parse_channel_list("(@101:120,110:140)", max_channels=40) == list(range(101, 141))
    with pytest.raises(ValueError, match="41 channels"):
        scpi.parse_channel_list("(@101:120,110:141)", max_channels=40)
    with pytest.raises(ValueError, match="99999999 channels"):  # counted, not expanded: returns at once
        scpi.parse_channel_list("(@1:99999999)", max_channels=60)


# -- against the emulator ----------------------------------------------------------------------------------

@pytest.fixture
def emulated():
    temps = {101: 20.0, 102: 60.0, 103: -40.0, 104: 300.0}
    emu = ScpiInstrumentEmulator(TemperatureResistances(lambda: temps), clock=ManualClock())
    registry.register("pt-test", emu)
    s = Pt1000Scanner.open("sim://pt-test", [101, 102, 103, 104], timeout=0.02)
    s.reset()
    yield s, emu, temps
    registry.unregister("pt-test")


@pytest.mark.parametrize("mode", ["fres", "frtd"])
def test_emulator_round_trip(emulated, mode: str) -> None:
    s, _, temps = emulated
    s.mode = mode
    s.configure()
    assert s.identify().startswith("Keysight")
    for r in s.read():
        assert r.status == "ok" and r.temperature_c == pytest.approx(temps[r.channel], abs=1e-6)
    s.initiate()
    assert [r.temperature_c for r in s.fetch()] == pytest.approx(list(temps.values()), abs=1e-6)


def test_emulator_open_and_short(emulated) -> None:
    s, emu, _ = emulated
    emu.provider = ConstantResistances({101: math.inf, 102: 2.0, 103: math.nan, 104: 1000.0})
    assert [r.status for r in s.read()] == ["open", "short", "open", "ok"]


def test_emulator_error_queue_entry(emulated) -> None:
    s, emu, _ = emulated
    emu.inject_error(-310, "System error")
    readings = s.read()
    assert len(readings) == 4 and all(r.status == "ok" for r in readings)
    assert [(e.code, e.text) for e in s.error_log] == [(-310, "System error")]
    assert s.read() and len(s.error_log) == 1


def test_emulator_unknown_command_reported(emulated) -> None:
    s, emu, _ = emulated
    s._write("FOO:BAR 1")
    assert s.drain_errors() == [(-113, "Undefined header")]


def test_emulator_mute_and_damaged_replies(emulated) -> None:
    s, emu, _ = emulated
    emu.mute = True
    with pytest.raises(DeviceTimeout):
        s.read()
    emu.mute = False
    emu.corrupt_next_reply("truncate")
    with pytest.raises(DeviceTimeout):
        s.read()
    emu.corrupt_next_reply("garbage")
    with pytest.raises(InstrumentError):
        s.read()
    assert len(s.read()) == 4


def test_emulator_disconnect_and_reconnect(emulated) -> None:
    s, emu, temps = emulated
    emu.connected = False
    with pytest.raises(ConnectionLost):
        s.read()
    with pytest.raises(ConnectionLost):
        s.reconnect()
    emu.connected = True
    s.reconnect()
    assert [r.temperature_c for r in s.read()] == pytest.approx(list(temps.values()), abs=1e-6)


def test_open_bad_url() -> None:
    with pytest.raises(ConnectionLost):
        Pt1000Scanner.open("nonsense://x", [101])


def test_public_failures_are_driver_errors(emulated) -> None:
    """Each way the scanner fails raises its own DriverError subclass, never a bare ValueError or OSError."""
    s, emu, _ = emulated

    def muted() -> None:
        emu.mute = True
        try:
            s.read()
        finally:
            emu.mute = False

    def garbled() -> None:
        emu.corrupt_next_reply("garbage")
        s.read()

    port_that_will_not_close = ScriptedSerial([], close_error=OSError(5, "Input/output error"))
    cases = [
        (lambda: Pt1000Scanner(ScriptedSerial([]), [101], mode="dcv"), DriverConfigError, False),
        (lambda: Pt1000Scanner(ScriptedSerial([]), []), DriverConfigError, False),
        (lambda: s.convert(999, 1000.0, 0.0), DriverConfigError, False),
        (lambda: Pt1000Scanner.open("nonsense://x", [101]), ConnectionLost, False),
        (muted, DeviceTimeout, False),
        (garbled, InstrumentError, False),
        (s.read, ConnectionLost, True),
        (s.reconnect, ConnectionLost, True),
        (Pt1000Scanner(port_that_will_not_close, [101]).close, ConnectionLost, False),
    ]
    for action, expected, unplug in cases:
        with pytest.raises(DriverError) as exc, registry.unplugged(emu) if unplug else nullcontext():
            action()
        assert type(exc.value) is expected, (action, exc.value)
    assert isinstance(DriverConfigError("x"), ValueError)  # callers that checked arguments with ValueError


def test_device_timeout_is_caught_as_timeout_error(emulated) -> None:
    s, emu, _ = emulated
    emu.mute = True
    caught: BaseException | None = None
    try:
        s.read()
    except TimeoutError as exc:
        caught = exc
    assert isinstance(caught, DeviceTimeout)


# -- fuzzing ---------------------------------------------------------------------------------------------------

@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=80), st.integers(min_value=1, max_value=4))
def test_fuzz_reply_parser(reply: bytes, n: int) -> None:
    try:
        values = scpi.parse_values(reply, n)
    except InstrumentError:
        return
    assert len(values) == n and all(math.isfinite(v) for v in values)
    assert b",".join(reply.rstrip(b"\r\n").split(b",")) == reply.rstrip(b"\r\n")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(min_value=-1e6, max_value=1e6) | st.just(9.9e37), min_size=1, max_size=4),
       st.data())
def test_fuzz_reply_values_and_damage(values: list[float], data) -> None:
    reply = (",".join(f"{v:+.8E}" for v in values) + "\n").encode()
    assert scpi.parse_values(reply, len(values)) == pytest.approx([float(f"{v:+.8E}") for v in values])
    i = data.draw(st.integers(0, len(reply) - 1))
    damaged = reply[:i] + data.draw(st.sampled_from([b"", b",", b"x", b"\xff", b"E", b".."])) + reply[i + 1:]
    try:
        got = scpi.parse_values(damaged, len(values))
    except InstrumentError:
        return
    assert len(got) == len(values)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=60))
def test_fuzz_scanner_any_reply(reply: bytes) -> None:
    port = ScriptedSerial([(b"READ?\n", reply + b"\n"), NO_ERR, NO_ERR])
    s = Pt1000Scanner(port, [101, 102], clock=lambda: 0.0)
    try:
        readings = s.read()
    except (InstrumentError, DeviceTimeout):
        return
    for r in readings:
        assert (r.temperature_c is None) == (r.status != "ok")
        assert (r.resistance_ohm is None) == (r.status in ("open", "short"))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40))
def test_fuzz_error_parser(reply: bytes) -> None:
    try:
        code, text = scpi.parse_error(reply)
    except InstrumentError:
        return
    assert isinstance(code, int) and '"' not in text


def test_a_scan_is_collected_without_waiting_even_when_the_reply_comes_in_pieces() -> None:
    """The acquisition loop's path: start_scan() sends READ?, collect() takes only the bytes already there."""
    port = ScriptedSerial([(b"READ?\n", b""), (b"SYST:ERR?\n", b'-222,"Data out of range"\n'), NO_ERR], timeout=2.0)
    now = [100.0]
    s = Pt1000Scanner(port, (101, 102), clock=lambda: now[0])
    s.start_scan()
    assert s.scanning and s.collect() is None  # nothing there yet: returns at once
    port.deliver(b"+1.09734700E+03,")
    now[0] += 0.5
    assert s.collect() is None  # half a reply: still nothing, still not waiting
    port.deliver(b"+1.00000000E+03\n")
    a, b = s.collect()  # the reply, then the error queue drained in the same call
    assert (a.status, b.status, a.t_host) == ("ok", "ok", 100.5) and not s.scanning and port.finished
    assert [(e.code, e.t_host) for e in s.error_log] == [(-222, 100.5)]


def test_a_silent_instrument_times_out_on_the_loops_clock_not_by_blocking() -> None:
    port = ScriptedSerial([(b"READ?\n", b"")], timeout=2.0)
    now = [0.0]
    s = Pt1000Scanner(port, (101,), clock=lambda: now[0])
    s.start_scan()
    for t in (0.0, 1.0, 2.0):  # within the port's time-out: no reply, no error, no wait
        now[0] = t
        assert s.collect() is None
    now[0] = 2.01
    with pytest.raises(DeviceTimeout, match="READ"):
        s.collect()
    assert not s.scanning
