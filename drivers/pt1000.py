"""PT1000 scanning DMM (Keysight 34970A/34972A/DAQ970A SCPI dialect) over a pyserial port or URL.

Error policy: after every configuration command the SCPI error queue is drained and any entry raises
InstrumentError (a half-configured instrument must not measure). During acquisition the queue is drained
after each scan and entries are *recorded* in `error_log` (with host time), so one stray error never drops a
scan; a reply that cannot be parsed raises InstrumentError. Silence raises DeviceTimeout, a failing
transport ConnectionLost (then `reconnect()`). Open sensors (overload +9.9E37) and shorts (< `short_ohm`)
become readings with status "open"/"short" and no number; values outside −200…850 °C have status "range".
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import serial

from drivers import cvd, scpi
from drivers.errors import ConnectionLost, DeviceTimeout, DriverConfigError, InstrumentError

Mode = Literal["fres", "frtd"]
_MAX_ERRORS_DRAINED = 32


class SerialPort(Protocol):
    """The part of pyserial's Serial API the text drivers use."""

    timeout: float | None

    def write(self, data: bytes) -> int | None: ...
    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes: ...
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

    @classmethod
    def open(cls, url: str, channels: Sequence[int], *, baudrate: int = 115200, timeout: float = 2.0,
             **kwargs: Any) -> "Pt1000Scanner":
        """Open `url` (device path, socket://host:5025, loop://, sim://...) and wrap it; nothing is sent yet."""
        try:
            port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConnectionLost(f"cannot open {url}: {exc}") from exc
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
        try:
            values = scpi.parse_values(reply, len(self.channels))
        except InstrumentError as exc:
            raise InstrumentError(str(exc), tuple(self.drain_errors())) from None
        self.error_log.extend(ErrorRecord(t_host, code, text) for code, text in self.drain_errors())
        return [self.convert(ch, v, t_host) for ch, v in zip(self.channels, values)]

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
        return reply

    def _write(self, command: str) -> None:
        try:
            self.port.write(command.encode("ascii") + b"\n")
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeout(f"{command}: write timed out") from exc
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"{command}: {exc}") from exc
