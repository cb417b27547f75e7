"""ClutchSensorNode gateway driver: COBS/CRC frames from the PC node's serial port → typed flywheel samples.

Corrupt bytes never become numbers: chunks that fail COBS, length, CRC or version checks are counted and
dropped, and reported as one `frame_errors` event per second with the counts (never one per frame).
Sequence gaps (u16, wrapping; the node clock disambiguates multiple wraps) count lost frames; radio
drop-outs (no frame for more than `dropout_periods` periods) are reported as a `dropout_start` and a
`dropout_end` event with their span, never filled in. A node that rebooted (clock went backwards or the
NODE_RESET flag) is reported too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import serial

from drivers import cvd, node_frame
from drivers.errors import ConnectionLost, DriverConfigError, FrameError
from drivers.node_frame import NodeFrame
from drivers.timebase import ClockMap

SensorStatus = Literal["ok", "open", "short", "range", "fault"]
_MAX_CHUNK = 4 * node_frame.ENCODED_LEN
ERROR_WINDOW_S = 1.0
CorruptCounter = Literal["crc_errors", "malformed", "resyncs"]
_OPEN_BITS = (node_frame.CH1_OPEN, node_frame.CH2_OPEN)
_SHORT_BITS = (node_frame.CH1_SHORT, node_frame.CH2_SHORT)


class ByteStream(Protocol):
    """The part of pyserial's Serial API a byte-stream driver uses."""

    @property
    def in_waiting(self) -> int: ...
    def read(self, size: int = 1) -> bytes: ...
    def open(self) -> None: ...
    def close(self) -> None: ...
    def reset_input_buffer(self) -> None: ...


@dataclass(frozen=True, slots=True)
class NodeSample:
    """One frame from the flywheel: per channel resistance Ω / temperature °C (None unless status is "ok")."""

    seq: int
    node_time_ms: int
    t_host: float  # run-clock time the gateway received the frame
    t: float  # run-clock time the node measured it: its own clock mapped onto the run clock (drivers/timebase.py)
    resistance_ohm: tuple[float | None, float | None]
    temperature_c: tuple[float | None, float | None]
    sensor_status: tuple[SensorStatus, SensorStatus]
    supply_mv: int
    rssi_dbm: int
    lqi: int
    flags: int


@dataclass(frozen=True, slots=True)
class LinkEvent:
    """A radio drop-out start/end, a node reboot, or the corrupt chunks of one counting window.

    Drop-outs: `span_s` is the gap between the frames around it (at end). `frame_errors`: `span_s` is the
    counting window (from its first corrupt chunk to the report, about `ERROR_WINDOW_S`), `lost_frames` the
    chunks dropped in it as corrupt (`crc_errors` + `malformed`); `resyncs` counts the times the parser lost
    frame sync in it (chunk before the first delimiter, or an over-long run without one).
    """

    kind: Literal["dropout_start", "dropout_end", "node_reset", "frame_errors"]
    t_host: float
    last_seq: int | None
    span_s: float | None = None
    lost_frames: int = 0
    crc_errors: int = 0
    malformed: int = 0
    resyncs: int = 0


@dataclass(slots=True)
class GatewayStats:
    """Counters of what the parser saw; every byte received lands in exactly one outcome."""

    frames_ok: int = 0
    crc_errors: int = 0
    malformed: int = 0
    lost: int = 0
    resyncs: int = 0
    dropouts: int = 0
    duplicates: int = 0
    node_resets: int = 0


@dataclass(slots=True)
class _ErrorWindow:
    """Corrupt chunks counted since `t0`, reported together as one `frame_errors` event."""

    t0: float
    crc_errors: int = 0
    malformed: int = 0
    resyncs: int = 0


class ClutchNodeGateway:
    """Reads the PC node's serial stream; `poll()` in simulated time, `read()` for blocking real-time use."""

    def __init__(self, port: ByteStream | None, *, period_s: float = 0.05, dropout_periods: float = 5,
                 coefficients: Sequence[cvd.CvdCoefficients] = (cvd.PT1000, cvd.PT1000),
                 clock: Callable[[], float] = time.monotonic, short_ohm: float = 150.0) -> None:
        self.port, self.period_s, self.clock, self.short_ohm = port, period_s, clock, short_ohm
        self.dropout_s = dropout_periods * period_s
        self.coefficients = tuple(coefficients)
        self.stats = GatewayStats()
        self._events: list[LinkEvent] = []
        self._buf = b""
        self._synced = False
        self._last: NodeFrame | None = None
        self._last_host = clock()
        self.clock_map = ClockMap()  # the node's clock → run clock (anew after a node reboot)
        self._node_s = 0.0  # the node's clock in s, unwrapped, at the newest accepted frame
        self._in_dropout = False
        self._errors: _ErrorWindow | None = None

    @classmethod
    def open(cls, url: str, *, baudrate: int = 921600, **kwargs: Any) -> "ClutchNodeGateway":
        """Open the PC node's port by pyserial URL (non-blocking reads) and wrap it."""
        try:
            port = serial.serial_for_url(url, baudrate=baudrate, timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConnectionLost(f"cannot open {url}: {exc}") from exc
        return cls(port, **kwargs)

    def poll(self) -> list[NodeSample]:
        """Decode whatever bytes are waiting (never blocks) and check for radio silence."""
        if self.port is None:
            raise DriverConfigError("poll() needs a port; use feed() on a gateway without one")
        try:
            waiting = self.port.in_waiting
            data = self.port.read(waiting) if waiting else b""
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"gateway port: {exc}") from exc
        samples = self.feed(data) if data else []
        self.check_silence()
        return samples

    def read(self, count: int, timeout_s: float) -> list[NodeSample]:
        """Block (wall-clock) until at least `count` samples arrived or `timeout_s` passed; real-time use only."""
        samples: list[NodeSample] = []
        deadline = time.monotonic() + timeout_s
        while len(samples) < count and time.monotonic() < deadline:
            new = self.poll()
            samples += new
            if not new:
                time.sleep(min(self.period_s / 4, 0.01))
        return samples

    def feed(self, data: bytes) -> list[NodeSample]:
        """Parse a piece of the byte stream (any split is fine) and return the samples it completed."""
        now = self.clock()
        chunks = (self._buf + data).split(node_frame.DELIMITER)
        self._buf = chunks.pop()
        if len(self._buf) > _MAX_CHUNK:
            self._buf, self._synced = b"", False
            self._count_corrupt("resyncs", now)
        frames: list[tuple[NodeFrame, float, float, ClockMap]] = []
        for chunk in chunks:
            frame = self._decode(chunk, now)
            if frame is not None and self._accept(frame, now):
                frames.append((frame, now, self._node_s, self.clock_map))
                self.clock_map.observe(self._node_s, now)
        self._report_errors(now)
        return self._samples(frames)

    def pop_events(self) -> list[LinkEvent]:
        """Link events since the last call, in the order they were noticed."""
        events, self._events = self._events, []
        return events

    def check_silence(self) -> None:
        """Report a drop-out once no frame arrived for longer than `dropout_periods` periods."""
        now = self.clock()
        if not self._in_dropout and now - self._last_host > self.dropout_s:
            self._start_dropout(now)
        self._report_errors(now)

    def reconnect(self) -> None:
        """Reopen the port; the partial frame in the buffer is dropped and the parser resynchronises."""
        if self.port is None:
            raise DriverConfigError("reconnect() needs a port")
        try:
            self.port.close()
            self.port.open()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"reconnect failed: {exc}") from exc
        self._buf, self._synced = b"", False

    def close(self) -> None:
        """Close the port; corrupt chunks of the running counting window are reported (`pop_events`)."""
        self._report_errors(self.clock(), final=True)
        if self.port is None:
            return
        try:
            self.port.close()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"close failed: {exc}") from exc

    def _decode(self, chunk: bytes, now: float) -> NodeFrame | None:
        synced, self._synced = self._synced, True
        if not chunk:
            return None
        try:
            return node_frame.decode(chunk)
        except FrameError as exc:
            if not synced:
                self._count_corrupt("resyncs", now)
            elif isinstance(exc, node_frame.CrcMismatch):
                self._count_corrupt("crc_errors", now)
            else:
                self._count_corrupt("malformed", now)
            return None

    def _count_corrupt(self, counter: CorruptCounter, now: float) -> None:
        """Count a corrupt chunk in the gateway's counters and in the running counting window."""
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        if self._errors is None:
            self._errors = _ErrorWindow(now)
        setattr(self._errors, counter, getattr(self._errors, counter) + 1)

    def _report_errors(self, now: float, final: bool = False) -> None:
        """One `frame_errors` event for the window once it is `ERROR_WINDOW_S` old (or `final`)."""
        window = self._errors
        if window is None or (not final and now - window.t0 < ERROR_WINDOW_S):
            return
        self._events.append(LinkEvent(
            "frame_errors", now, self._last.seq if self._last else None, now - window.t0,
            window.crc_errors + window.malformed, window.crc_errors, window.malformed, window.resyncs))
        self._errors = None

    def _start_dropout(self, t: float) -> None:
        """The one place a drop-out begins, so that every `dropout_end` has exactly one `dropout_start`."""
        self._in_dropout = True
        self.stats.dropouts += 1
        self._events.append(LinkEvent("dropout_start", t, self._last.seq if self._last else None))

    def _accept(self, frame: NodeFrame, now: float) -> bool:
        """Sequence bookkeeping; False for a duplicate. Emits reset and drop-out events.

        A gap longer than the drop-out limit that fell between two polls was never seen as silence by
        `check_silence` (the host polls slower than the limit, e.g. 1 s ticks against 0.25 s): its
        `dropout_start` is emitted here, dated when the silence passed the limit, before its end.
        """
        last, stats = self._last, self.stats
        host_span = now - self._last_host
        lost, span, reset = 0, host_span, False
        if last is not None:
            seq_gap = (frame.seq - last.seq) & 0xFFFF
            node_dt = (frame.node_time_ms - last.node_time_ms) & 0xFFFFFFFF
            if seq_gap == 0 and node_dt == 0:
                stats.duplicates += 1
                return False
            reset = bool(frame.flags & node_frame.NODE_RESET) or node_dt >= 1 << 31
            if not reset:
                self._node_s += node_dt / 1000
            if reset:
                stats.node_resets += 1
                lost = max(0, round(host_span / self.period_s) - 1)
            else:
                wraps = max(0, round((node_dt / (1000 * self.period_s) - seq_gap) / 65536))
                lost = seq_gap - 1 + 65536 * wraps
                span = node_dt / 1000
        stats.lost += lost
        if last is not None and span > self.dropout_s and not self._in_dropout:
            self._start_dropout(min(now, max(self._last_host, now - span) + self.dropout_s))
        if reset or last is None:  # a new node clock: counted from this frame, mapped afresh
            self._node_s, self.clock_map = frame.node_time_ms / 1000, ClockMap()
        if reset:
            self._events.append(LinkEvent("node_reset", now, last.seq if last else None, host_span, lost))
        if self._in_dropout:
            self._events.append(LinkEvent("dropout_end", now, last.seq if last else None, span, lost))
            self._in_dropout = False
        stats.frames_ok += 1
        self._last, self._last_host = frame, now
        return True

    def _samples(self, frames: list[tuple[NodeFrame, float, float, ClockMap]]) -> list[NodeSample]:
        samples = []
        for f, t_host, node_s, clock_map in frames:
            ohm = (f.r_mohm[0] / 1000.0, f.r_mohm[1] / 1000.0)
            deg = (cvd.temperature(ohm[0], self.coefficients[0]), cvd.temperature(ohm[1], self.coefficients[1]))
            s1, s2 = self._status(f, 0, ohm[0], deg[0]), self._status(f, 1, ohm[1], deg[1])
            samples.append(NodeSample(
                f.seq, f.node_time_ms, t_host, min(clock_map.to_run(node_s), t_host),
                (ohm[0] if s1 in ("ok", "range") else None, ohm[1] if s2 in ("ok", "range") else None),
                (deg[0] if s1 == "ok" else None, deg[1] if s2 == "ok" else None),
                (s1, s2), f.supply_mv, f.rssi_dbm, f.lqi, f.flags))
        return samples

    def _status(self, frame: NodeFrame, ch: int, ohm: float, deg: float) -> SensorStatus:
        if frame.flags & _OPEN_BITS[ch]:
            return "open"
        if frame.flags & _SHORT_BITS[ch]:
            return "short"
        if frame.flags & node_frame.ADC_FAULT or frame.r_mohm[ch] == node_frame.NO_VALUE:
            return "fault"
        if ohm < self.short_ohm:
            return "short"
        return "ok" if cvd.T_MIN_C <= deg <= cvd.T_MAX_C else "range"
