"""ClutchSensorNode gateway driver: COBS/CRC frames from the PC node's serial port → typed flywheel samples.

Corrupt bytes never become numbers: chunks that fail COBS, length, CRC or version checks are counted and
dropped. Sequence gaps (u16, wrapping; the node clock disambiguates multiple wraps) count lost frames;
radio drop-outs (no frame for more than `dropout_periods` periods) are reported as events with their span,
never filled in. A node that rebooted (clock went backwards or the NODE_RESET flag) is reported too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import serial

from drivers import cvd, node_frame
from drivers.errors import ConnectionLost
from drivers.node_frame import NodeFrame

SensorStatus = Literal["ok", "open", "short", "range", "fault"]
_MAX_CHUNK = 4 * node_frame.ENCODED_LEN
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
    t_host: float
    resistance_ohm: tuple[float | None, float | None]
    temperature_c: tuple[float | None, float | None]
    sensor_status: tuple[SensorStatus, SensorStatus]
    supply_mv: int
    rssi_dbm: int
    lqi: int
    flags: int


@dataclass(frozen=True, slots=True)
class LinkEvent:
    """A radio drop-out start/end or a node reboot; `span_s` is the gap between the frames around it (at end)."""

    kind: Literal["dropout_start", "dropout_end", "node_reset"]
    t_host: float
    last_seq: int | None
    span_s: float | None = None
    lost_frames: int = 0


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
        self._in_dropout = False

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
        assert self.port is not None, "poll() needs a port; use feed() without one"
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
        chunks = (self._buf + data).split(node_frame.DELIMITER)
        self._buf = chunks.pop()
        if len(self._buf) > _MAX_CHUNK:
            self._buf, self._synced = b"", False
            self.stats.resyncs += 1
        frames: list[tuple[NodeFrame, float]] = []
        now = self.clock()
        for chunk in chunks:
            frame = self._decode(chunk)
            if frame is not None and self._accept(frame, now):
                frames.append((frame, now))
        return self._samples(frames)

    def pop_events(self) -> list[LinkEvent]:
        """Link events since the last call, oldest first."""
        events, self._events = self._events, []
        return events

    def check_silence(self) -> None:
        """Report a drop-out once no frame arrived for longer than `dropout_periods` periods."""
        now = self.clock()
        if not self._in_dropout and now - self._last_host > self.dropout_s:
            self._in_dropout = True
            self.stats.dropouts += 1
            self._events.append(LinkEvent("dropout_start", now, self._last.seq if self._last else None))

    def reconnect(self) -> None:
        """Reopen the port; the partial frame in the buffer is dropped and the parser resynchronises."""
        assert self.port is not None
        try:
            self.port.close()
            self.port.open()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"reconnect failed: {exc}") from exc
        self._buf, self._synced = b"", False

    def close(self) -> None:
        """Close the port."""
        if self.port is not None:
            self.port.close()

    def _decode(self, chunk: bytes) -> NodeFrame | None:
        synced, self._synced = self._synced, True
        if not chunk:
            return None
        try:
            return node_frame.decode(chunk)
        except node_frame.FrameError as exc:
            if not synced:
                self.stats.resyncs += 1
            elif isinstance(exc, node_frame.CrcMismatch):
                self.stats.crc_errors += 1
            else:
                self.stats.malformed += 1
            return None

    def _accept(self, frame: NodeFrame, now: float) -> bool:
        """Sequence bookkeeping; False for a duplicate. Emits reset and drop-out-end events."""
        last, stats = self._last, self.stats
        host_span = now - self._last_host
        lost, span = 0, host_span
        if last is not None:
            seq_gap = (frame.seq - last.seq) & 0xFFFF
            node_dt = (frame.node_time_ms - last.node_time_ms) & 0xFFFFFFFF
            if seq_gap == 0 and node_dt == 0:
                stats.duplicates += 1
                return False
            if frame.flags & node_frame.NODE_RESET or node_dt >= 1 << 31:
                stats.node_resets += 1
                lost = max(0, round(host_span / self.period_s) - 1)
                self._events.append(LinkEvent("node_reset", now, last.seq, host_span, lost))
            else:
                wraps = max(0, round((node_dt / (1000 * self.period_s) - seq_gap) / 65536))
                lost = seq_gap - 1 + 65536 * wraps
                span = node_dt / 1000
        stats.lost += lost
        if self._in_dropout or (last is not None and span > self.dropout_s):
            if not self._in_dropout:
                stats.dropouts += 1
            self._events.append(LinkEvent("dropout_end", now, last.seq if last else None, span, lost))
            self._in_dropout = False
        stats.frames_ok += 1
        self._last, self._last_host = frame, now
        return True

    def _samples(self, frames: list[tuple[NodeFrame, float]]) -> list[NodeSample]:
        samples = []
        for f, t_host in frames:
            ohm = (f.r_mohm[0] / 1000.0, f.r_mohm[1] / 1000.0)
            deg = (cvd.temperature(ohm[0], self.coefficients[0]), cvd.temperature(ohm[1], self.coefficients[1]))
            s1, s2 = self._status(f, 0, ohm[0], deg[0]), self._status(f, 1, ohm[1], deg[1])
            samples.append(NodeSample(
                f.seq, f.node_time_ms, t_host,
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
