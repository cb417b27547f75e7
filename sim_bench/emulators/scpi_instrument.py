"""Emulated Keysight 34970A/DAQ970A scanning DMM: SCPI lines in, replies out, resistances from a provider.

A serial endpoint (see registry.py): open it as `sim://NAME`. Everything happens at `write()`; replies wait in
the output buffer. Fault hooks: `inject_error`, `mute`, `corrupt_next_reply`, `connected = False`.
"""

from __future__ import annotations

import math
import re
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Literal

from drivers import cvd, scpi
from sim_bench.emulators.providers import ConstantResistances, ResistanceProvider

_NO_ERROR = '+0,"No error"'
_QUEUE_SIZE = 10


def _header(pattern: str) -> re.Pattern[str]:
    """Regex matching a SCPI header in short or long form, e.g. "[SENSe:]TEMPerature" → SENS:TEMP, TEMPERATURE…"""
    def keyword(m: re.Match[str]) -> str:
        word = m.group(0)
        short = "".join(c for c in word if c.isupper() or c in "*?")
        return f"(?:{re.escape(word.upper())}|{re.escape(short)})" if short != word.upper() else re.escape(word)
    body = re.sub(r"[*A-Za-z?]+", keyword, pattern)
    return re.compile(":?" + body.replace("[", "(?:").replace("]", ")?"))


class ScpiInstrumentEmulator:
    """The SCPI subset benchlab uses: *IDN? *RST *CLS *OPC? CONF:FRES CONF:TEMP FRTD TEMP:TRAN:FRTD:RES:REF
    UNIT:TEMP ROUT:SCAN READ? INIT FETC? SYST:ERR?; unknown headers queue -113 like the real instrument."""

    def __init__(self, provider: ResistanceProvider | None = None, *, clock: Callable[[], float] = time.monotonic,
                 idn: str = "Keysight Technologies,DAQ970A,SIM0000001,A.03.02-sim",
                 channels: Iterable[int] = range(101, 121)) -> None:
        self.provider = provider or ConstantResistances()
        self.clock, self.idn = clock, idn
        self.valid_channels = frozenset(channels)
        self.connected = True
        self.mute = False
        self.commands: deque[str] = deque(maxlen=1000)
        self._reply_fault: Literal["truncate", "garbage"] | None = None
        self._in = b""
        self._out = bytearray()
        self._handlers = [(_header(p), h) for p, h in (
            ("*IDN?", self._idn), ("*RST", self._rst), ("*CLS", self._cls), ("*OPC?", lambda a: "1"),
            ("SYSTem:ERRor[:NEXT]?", self._err), ("CONFigure:FRESistance", self._conf_fres),
            ("CONFigure:TEMPerature", self._conf_temp), ("UNIT:TEMPerature", self._unit),
            ("[SENSe:]TEMPerature:TRANsducer:FRTD:RESistance[:REFerence]", self._frtd_ref),
            ("ROUTe:SCAN", self._scan_list), ("READ?", self._read), ("INITiate[:IMMediate]", self._init),
            ("FETCh?", self._fetch))]
        self._handler_of: dict[str, Callable[[str], str | None] | None] = {}  # header -> its handler, once matched
        self._rst("")

    # -- serial endpoint -----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        """Bytes from the host; every complete line is executed at once."""
        *lines, self._in = (self._in + data).split(b"\n")
        for line in lines:
            reply = self.handle(line.decode("ascii", "replace").strip())
            if reply is not None and not self.mute:
                self._out += self._damage(reply.encode("ascii") + b"\n")

    def read_available(self) -> bytes:
        """Reply bytes waiting for the host."""
        if not self._out:
            return b""
        data, self._out = bytes(self._out), bytearray()
        return data

    # -- fault hooks ---------------------------------------------------------------------------------
    def inject_error(self, code: int, text: str) -> None:
        """Put an entry in the error queue, as the instrument does for a self-test or overload problem."""
        self._push_error(code, text)

    def corrupt_next_reply(self, how: Literal["truncate", "garbage"]) -> None:
        """Damage the next reply: cut it in half (no terminator) or overwrite it with non-numeric bytes."""
        self._reply_fault = how

    # -- SCPI ------------------------------------------------------------------------------------------
    def handle(self, line: str) -> str | None:
        """Execute one command line and return the reply text (None for commands without reply)."""
        if not line:
            return None
        self.commands.append(line)
        header, _, args = line.partition(" ")
        try:
            handler = self._handler_of[header]
        except KeyError:
            handler = self._handler_of[header] = self._match(header)
        if handler is None:
            self._push_error(-113, "Undefined header")
            return None
        try:
            return handler(args.strip())
        except ValueError:
            self._push_error(-224, "Illegal parameter value")
            return None

    def _match(self, header: str) -> Callable[[str], str | None] | None:
        """The handler of a command header (short or long form, any case), None if the instrument has none."""
        upper = header.upper()
        return next((handler for pattern, handler in self._handlers if pattern.fullmatch(upper)), None)

    def _idn(self, args: str) -> str:
        return self.idn

    def _rst(self, args: str) -> None:
        self.config: dict[int, str] = {}
        self.ref_ohm: dict[int, float] = {}
        self.scan: list[int] = []
        self.last_scan: list[float] | None = None
        self.errors: list[str] = []

    def _cls(self, args: str) -> None:
        self.errors = []

    def _err(self, args: str) -> str:
        return self.errors.pop(0) if self.errors else _NO_ERROR

    def _conf_fres(self, args: str) -> None:
        for ch in self._channels(args[args.index("(@"):]):
            self.config[ch] = "fres"

    def _conf_temp(self, args: str) -> None:
        head, _, chans = args.partition("(@")
        params = [p.strip().upper() for p in head.rstrip(", ").split(",")]
        if params[0] not in ("FRTD", "RTD") or params[1:] not in ([], ["85"], ["DEF"]):
            raise ValueError(args)
        for ch in self._channels("(@" + chans):
            self.config[ch] = "frtd"
            self.ref_ohm[ch] = 100.0

    def _unit(self, args: str) -> None:
        if not args.upper().startswith("C"):
            raise ValueError(args)

    def _frtd_ref(self, args: str) -> None:
        value, _, chans = args.partition(",")
        for ch in self._channels(chans):
            if self.config.get(ch) != "frtd":
                self._push_error(-221, "Settings conflict")
                return
            self.ref_ohm[ch] = float(value)

    def _scan_list(self, args: str) -> None:
        channels = self._channels(args)
        if any(ch not in self.config for ch in channels):
            self._push_error(-221, "Settings conflict")
            return
        self.scan = channels

    def _init(self, args: str) -> None:
        if not self.scan:
            self._push_error(-221, "Settings conflict")
            return
        self.last_scan = self._measure()

    def _fetch(self, args: str) -> str | None:
        if self.last_scan is None:
            self._push_error(-230, "Data stale")
            return None
        return ",".join(["%+.8E"] * len(self.last_scan)) % tuple(self.last_scan)

    def _read(self, args: str) -> str | None:
        self._init(args)
        return self._fetch(args) if self.scan else None

    def _measure(self) -> list[float]:
        ohms = self.provider.get_resistances()
        values = []
        for ch in self.scan:
            r = ohms.get(ch, math.inf)
            if not math.isfinite(r) or r < 0:
                values.append(scpi.OVERLOAD)
            elif self.config[ch] == "fres":
                values.append(r)
            else:
                values.append(float(cvd.temperature(r * 1000.0 / self.ref_ohm[ch])))
        return values

    def _channels(self, text: str) -> list[int]:
        channels = scpi.parse_channel_list(text)
        if not channels or any(ch not in self.valid_channels for ch in channels):
            raise ValueError(text)
        return channels

    def _push_error(self, code: int, text: str) -> None:
        if len(self.errors) < _QUEUE_SIZE:
            self.errors.append(f'{code:+d},"{text}"')
        else:
            self.errors[-1] = '-350,"Queue overflow"'

    def _damage(self, reply: bytes) -> bytes:
        fault, self._reply_fault = self._reply_fault, None
        if fault == "truncate":
            return reply[: len(reply) // 2]
        if fault == "garbage":
            return b"#\xff" + reply[2:]
        return reply
