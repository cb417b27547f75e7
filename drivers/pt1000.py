"""PT1000 scanning DMM (Keysight 34970A/34972A/DAQ970A SCPI dialect) over a pyserial port or URL, or a VISA resource.

Error policy: after every configuration command the SCPI error queue is drained and any entry raises
InstrumentError (a half-configured instrument must not measure). During acquisition the queue is drained
after each scan and entries are *recorded* in `error_log` (with host time), so one stray error never drops a
scan; a reply that cannot be parsed raises InstrumentError. Silence raises DeviceTimeout, a failing
transport ConnectionLost (then `reconnect()`). Open sensors (overload +9.9E37) and shorts (< `short_ohm`)
become readings with status "open"/"short" and no number; values outside −200…850 °C have status "range".

Two ways to scan: `read()` waits for the reply (probe, scripts); `start_scan()` + `collect()` never wait
(the runner's loop, which must keep CAN frames cyclic and interlocks watched while a silent instrument
times out on the loop's own clock).

The SCPI dialogue (commands and replies) is logged at DEBUG on logger `drivers.pt1000`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import serial

from drivers import cvd, scpi
from drivers.errors import ConnectionLost, DeviceTimeout, DriverConfigError, InstrumentError
from drivers.visa_port import VisaPort, is_visa_resource

log = logging.getLogger(__name__)
Mode = Literal["fres", "frtd"]
_MAX_ERRORS_DRAINED = 32


class SerialPort(Protocol):
    """The part of pyserial's Serial API the text drivers use."""

    timeout: float | None

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes: ...
    @property
    def in_waiting(self) -> int: ...
    def reset_input_buffer(self) -> None: ...
    def open(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True, slots=True)
class Pt1000Reading:
    """One channel of one scan; `resistance_ohm`/`temperature_c` are None whenever `status` says there is no number."""

    channel: int
    t_host: float
    resistance_ohm: float | None
    temperature_c: float | None
    status: Literal["ok", "open", "short", "range"]


@dataclass(frozen=True, slots=True)
class ErrorRecord:
    """An instrument error-queue entry seen during acquisition, with the host time it was drained."""

    t_host: float
    code: int
    text: str


class Pt1000Scanner:
    """Scans PT1000 channels in 4-wire resistance (`fres`, CVD in software) or RTD temperature (`frtd`) mode."""

    def __init__(self, port: SerialPort, channels: Sequence[int], *, mode: Mode = "fres",
                 coefficients: Mapping[int, cvd.CvdCoefficients] | None = None,
                 clock: Callable[[], float] = time.monotonic, short_ohm: float = 150.0) -> None:
        if mode not in ("fres", "frtd"):
            raise DriverConfigError(f"mode must be 'fres' or 'frtd', not {mode!r}")
        if not channels:
            raise DriverConfigError("at least one channel is needed")
        self.port, self.mode, self.clock, self.short_ohm = port, mode, clock, short_ohm
        self.channels = sorted(set(channels))
        self.coefficients = {ch: (coefficients or {}).get(ch, cvd.PT1000) for ch in self.channels}
        self.error_log: list[ErrorRecord] = []
        self._scan_steps: Generator[None, None, list[Pt1000Reading]] | None = None
        self._rx = bytearray()

    @classmethod
    def open(cls, url: str, channels: Sequence[int], *, baudrate: int = 115200, timeout: float = 2.0,
             **kwargs: Any) -> "Pt1000Scanner":
        """Open `url` and wrap it; nothing is sent yet. `url` is a pyserial URL (device path, socket://host:5025,
        loop://, sim://...) or a VISA resource string (TCPIP0::10.0.0.5::inst0::INSTR, GPIB0::9::INSTR,
        TCPIP0::host::5025::SOCKET), opened through PyVISA (drivers/visa_port.py).

        ConnectionLost if it does not open, caused by the transport's own error (pyserial's SerialException,
        OSError, ValueError for a bad URL or baud rate; ImportError/OSError where a VISA library is missing).
        """
        try:
            if is_visa_resource(url):
                port: SerialPort = VisaPort(url, timeout=timeout)
            else:
                port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout)
        except (serial.SerialException, OSError, ValueError, ImportError) as exc:
            raise ConnectionLost(f"cannot open {url}: {exc}") from exc
        log.info("scanner %s open (timeout %g s)", url, timeout)
        return cls(port, channels, **kwargs)

    def identify(self) -> str:
        """The instrument's `*IDN?` string (maker, model, serial, firmware)."""
        return self._query("*IDN?").decode("ascii", "replace").strip()

    def reset(self) -> None:
        """`*RST` and `*CLS`, then configure the scan: a known state whatever ran before."""
        self._command("*RST", "*CLS")
        self.configure()

    def configure(self) -> None:
        """Configure the channels for the mode and make them the scan list; raises InstrumentError on any error."""
        chans = scpi.channel_list(self.channels)
        if self.mode == "fres":
            commands = [f"CONF:FRES {chans}"]
        else:
            commands = [f"CONF:TEMP FRTD,85,{chans}", f"TEMP:TRAN:FRTD:RES:REF 1000,{chans}", f"UNIT:TEMP C,{chans}"]
        self._command(*commands, f"ROUT:SCAN {chans}")

    def read(self) -> list[Pt1000Reading]:
        """Run one scan (`READ?`) and return a reading per channel; instrument errors go to `error_log`."""
        return self._scan("READ?")

    def start_scan(self) -> None:
        """Send `READ?` and return at once; `collect()` gathers the reply without ever blocking (acquisition loops)."""
        self._rx.clear()
        try:
            self.port.reset_input_buffer()  # a late reply to an earlier, timed-out scan is not this scan's
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"READ?: {exc}") from exc
        self._scan_steps = self._scan_without_waiting(self.clock() + (self.port.timeout or 0.0))

    def collect(self) -> list[Pt1000Reading] | None:
        """The scan started by `start_scan()` if its reply (and the error queue's) has arrived, else None.

        Never waits: a loop that also keeps CAN frames cyclic and interlocks watched calls it every tick.
        DeviceTimeout once the port's time-out has passed on the loop's clock; ConnectionLost if the port fails.
        """
        if self._scan_steps is None:
            raise DriverConfigError("collect() without start_scan()")
        try:
            next(self._scan_steps)
            return None
        except StopIteration as done:
            self._scan_steps = None
            return done.value
        except BaseException:
            self._scan_steps = None
            raise

    @property
    def scanning(self) -> bool:
        """A scan was started and is not collected yet."""
        return self._scan_steps is not None

    def initiate(self) -> None:
        """Start a scan (`INIT`) without waiting; collect it later with `fetch()`."""
        self._write("INIT")

    def fetch(self) -> list[Pt1000Reading]:
        """Readings of the scan started by `initiate()` (`FETC?`)."""
        return self._scan("FETC?")

    def drain_errors(self) -> list[tuple[int, str]]:
        """Empty the instrument's error queue (`SYST:ERR?` until code 0) and return its entries."""
        entries = []
        for _ in range(_MAX_ERRORS_DRAINED):
            code, text = scpi.parse_error(self._query("SYST:ERR?"))
            if code == 0:
                return entries
            entries.append((code, text))
        raise InstrumentError("error queue does not empty", tuple(entries))

    def reconnect(self) -> None:
        """Close and reopen the transport, then reset and configure the instrument."""
        try:
            self.port.close()
            self.port.open()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"reconnect failed: {exc}") from exc
        self.reset()

    def close(self) -> None:
        """Close the transport."""
        try:
            self.port.close()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"close failed: {exc}") from exc

    def convert(self, channel: int, value: float, t_host: float) -> Pt1000Reading:
        """Turn one raw instrument value (Ω in fres mode, °C in frtd mode) into a reading with its status."""
        if channel not in self.coefficients:
            raise DriverConfigError(f"channel {channel} is not in the scan list {self.channels}")
        if not math.isfinite(value) or abs(value) >= scpi.OVERLOAD:
            return Pt1000Reading(channel, t_host, None, None, "open")
        if self.mode == "fres":
            ohm, deg = value, float(cvd.temperature(value, self.coefficients[channel]))
        else:
            ohm, deg = float(cvd.resistance(value)), value
        if ohm < self.short_ohm:
            return Pt1000Reading(channel, t_host, None, None, "short")
        if not cvd.in_range(deg):
            return Pt1000Reading(channel, t_host, ohm, None, "range")
        return Pt1000Reading(channel, t_host, ohm, deg, "ok")

    def _scan(self, query: str) -> list[Pt1000Reading]:
        reply = self._query(query)
        t_host = self.clock()
        return self._readings(reply, t_host, self.drain_errors())

    def _readings(self, reply: bytes, t_host: float, errors: list[tuple[int, str]]) -> list[Pt1000Reading]:
        """A scan's reply as readings, its error-queue entries logged; a reply that is not a scan raises them."""
        try:
            values = scpi.parse_values(reply, len(self.channels))
        except InstrumentError as exc:
            raise InstrumentError(str(exc), tuple(errors)) from None
        self.error_log.extend(ErrorRecord(t_host, code, text) for code, text in errors)
        return [self.convert(ch, v, t_host) for ch, v in zip(self.channels, values)]

    def _scan_without_waiting(self, deadline: float) -> Generator[None, None, list[Pt1000Reading]]:
        """`READ?`, its reply, then the error queue (`SYST:ERR?` until 0), yielding whenever a reply is not complete."""
        self._write("READ?")
        reply = yield from self._line("READ?", deadline)
        t_host = self.clock()
        entries = []
        for _ in range(_MAX_ERRORS_DRAINED):
            self._write("SYST:ERR?")
            code, text = scpi.parse_error((yield from self._line("SYST:ERR?", deadline)))
            if code == 0:
                break
            entries.append((code, text))
        return self._readings(reply, t_host, entries)

    def _line(self, command: str, deadline: float) -> Generator[None, None, bytes]:
        """The next reply line, taking only the bytes already there; yields while it is incomplete."""
        while True:
            try:  # everything already there: pyserial's socket:// says 1 byte waiting whenever any is
                while b"\n" not in self._rx and (waiting := self.port.in_waiting):
                    self._rx += self.port.read(waiting)
            except (serial.SerialException, OSError) as exc:
                raise ConnectionLost(f"{command}: {exc}") from exc
            end = self._rx.find(b"\n")
            if end >= 0:
                line = bytes(self._rx[:end + 1])
                del self._rx[:end + 1]
                log.debug("SCPI < %r", line)
                return line
            if self.clock() > deadline:
                raise DeviceTimeout(f"{command}: no complete reply within {self.port.timeout} s "
                                    f"(got {bytes(self._rx[:40])!r})")
            yield

    def _command(self, *commands: str) -> None:
        for command in commands:
            self._write(command)
        entries = self.drain_errors()
        if entries:
            raise InstrumentError(f"{'; '.join(commands)} failed", tuple(entries))

    def _query(self, command: str) -> bytes:
        try:
            self.port.reset_input_buffer()
            self._write(command)
            reply = self.port.read_until(b"\n")
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeout(f"{command}: write timed out") from exc
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"{command}: {exc}") from exc
        if not reply.endswith(b"\n"):
            raise DeviceTimeout(f"{command}: no complete reply within {self.port.timeout} s (got {reply[:40]!r})")
        log.debug("SCPI < %r", reply)
        return reply

    def _write(self, command: str) -> None:
        log.debug("SCPI > %s", command)
        try:
            self.port.write(command.encode("ascii") + b"\n")
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeout(f"{command}: write timed out") from exc
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"{command}: {exc}") from exc
