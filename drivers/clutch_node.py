"""ClutchSensorNode gateway driver: COBS/CRC frames from the PC node's serial port → typed flywheel samples.

Corrupt bytes never become numbers: chunks that fail COBS, length, CRC or version checks are counted and
dropped, and reported as one `frame_errors` event per second with the counts (never one per frame).
Sequence gaps (u16, wrapping; the node clock disambiguates multiple wraps) count lost frames; radio
drop-outs (no frame for more than `dropout_periods` periods) are reported as a `dropout_start` and a
`dropout_end` event with their span, never filled in. A node that rebooted (clock went backwards or the
NODE_RESET flag) is reported too.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
import serial
from numba import njit

from drivers import cvd, node_frame
from drivers.errors import ConnectionLost, DriverConfigError
from drivers.node_frame import NodeFrame
from drivers.timebase import ClockMap

SensorStatus = Literal["ok", "open", "short", "range", "fault"]
SENSOR_STATUSES: tuple[SensorStatus, ...] = ("ok", "open", "short", "range", "fault")  # NodeBlock.status indexes this
_OK, _OPEN, _SHORT, _RANGE, _FAULT = range(len(SENSOR_STATUSES))
_MAX_CHUNK = 4 * node_frame.ENCODED_LEN
ERROR_WINDOW_S = 1.0
CorruptCounter = Literal["crc_errors", "malformed", "resyncs"]
_NO_ROWS = np.zeros((0, len(node_frame.FIELDS)), dtype=np.int64)
_F = {name: j for j, name in enumerate(node_frame.FIELDS)}
_CORRUPT: dict[int, CorruptCounter] = {node_frame.BAD_CRC: "crc_errors", node_frame.BAD_LENGTH: "malformed",
                                       node_frame.BAD_COBS: "malformed", node_frame.BAD_PAYLOAD: "malformed",
                                       node_frame.BAD_VERSION: "malformed"}


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
class NodeBlock:
    """The samples of one read as columns, one row per accepted frame in the order received (NodeSample's fields;
    per channel NaN where NodeSample has None, the status as an index into SENSOR_STATUSES)."""

    seq: np.ndarray
    node_time_ms: np.ndarray
    t_host: float  # run-clock time the gateway received the frames
    t: np.ndarray  # run-clock time the node measured each (its own clock mapped onto the run clock)
    resistance_ohm: np.ndarray  # (n, 2)
    temperature_c: np.ndarray  # (n, 2)
    status: np.ndarray  # (n, 2)
    supply_mv: np.ndarray
    rssi_dbm: np.ndarray
    lqi: np.ndarray
    flags: np.ndarray

    def __len__(self) -> int:
        return len(self.seq)

    def samples(self) -> list[NodeSample]:
        """The block as one NodeSample per frame."""
        def value(v: float) -> float | None:
            return None if math.isnan(v) else v

        return [NodeSample(seq, t_ms, self.t_host, t, (value(r1), value(r2)), (value(d1), value(d2)),
                           (SENSOR_STATUSES[s1], SENSOR_STATUSES[s2]), supply, rssi, lqi, flags)
                for seq, t_ms, t, (r1, r2), (d1, d2), (s1, s2), supply, rssi, lqi, flags in zip(
                    self.seq.tolist(), self.node_time_ms.tolist(), self.t.tolist(), self.resistance_ohm.tolist(),
                    self.temperature_c.tolist(), self.status.tolist(), self.supply_mv.tolist(),
                    self.rssi_dbm.tolist(), self.lqi.tolist(), self.flags.tolist())]


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
        return self.poll_block().samples()

    def poll_block(self) -> NodeBlock:
        """`poll`, the samples as one block of columns."""
        if self.port is None:
            raise DriverConfigError("poll() needs a port; use feed() on a gateway without one")
        try:
            waiting = self.port.in_waiting
            data = self.port.read(waiting) if waiting else b""
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"gateway port: {exc}") from exc
        block = self.feed_block(data) if data else self._block(_NO_ROWS, self.clock())
        self.check_silence()
        return block

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
        return self.feed_block(data).samples()

    def feed_block(self, data: bytes) -> NodeBlock:
        """`feed`, the samples as one block of columns: every delimited chunk decoded in one compiled pass."""
        now = self.clock()
        rows, status, self._buf = node_frame.decode_stream(self._buf + data)
        if len(self._buf) > _MAX_CHUNK:
            self._buf, self._synced = b"", False
            self._count_corrupt("resyncs", now)
        if len(status):
            synced, self._synced = self._synced, True
            if status.any():  # not all frames: empty chunks are skipped, corrupt ones counted
                for k, code in enumerate(status.tolist()):
                    if code > node_frame.EMPTY:
                        self._count_corrupt(_CORRUPT[code] if synced or k else "resyncs", now)
                rows = rows[status == node_frame.OK]
        block = self._block(rows, now)
        self._report_errors(now)
        return block

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

    def _block(self, rows: np.ndarray, now: float) -> NodeBlock:
        """The accepted frames among `rows` (node_frame.FIELDS order, as received) as samples.

        A run of plainly consecutive frames (seq + 1, node clock forward by at most the drop-out limit, no reset flag,
        no drop-out running) is taken in one step; any other frame goes through `_accept`.
        """
        n = len(rows)
        last = self._last
        plain, span, all_plain = _plainly_consecutive(rows, last.seq if last else 0, last.node_time_ms if last else 0,
                                                      self.period_s, self.dropout_s)
        if all_plain and n and last is not None and not self._in_dropout:  # the usual read: one run of plain frames
            node_s = self._take_plain(rows, span, now)
            return self._columns(rows, np.minimum(self.clock_map.to_run(node_s), now), now)
        plain_list = plain.tolist()
        node_s, keep = np.empty(n), np.zeros(n, dtype=bool)
        runs: list[tuple[int, int, ClockMap]] = []  # accepted rows [i, j) and the node clock's map they belong to
        i = 0
        while i < n:
            if plain_list[i] and self._last is not None and not self._in_dropout:
                j = i + 1
                while j < n and plain_list[j]:
                    j += 1
                node_s[i:j] = self._take_plain(rows[i:j], span[i:j], now)
            else:
                j = i + 1
                if not self._accept(node_frame.frame_of(rows[i].tolist()), now):
                    i = j
                    continue
                node_s[i] = self._node_s
                self.clock_map.observe(self._node_s, now)
            keep[i:j] = True
            runs.append((i, j, self.clock_map))
            i = j
        t = np.empty(n)
        for i, j, clock_map in runs:
            t[i:j] = np.minimum(clock_map.to_run(node_s[i:j]), now)
        return self._columns(rows[keep], t[keep], now)

    def _take_plain(self, rows: np.ndarray, span: np.ndarray, now: float) -> np.ndarray:
        """`_accept` of plainly consecutive frames in one step (nothing lost, no event): their node clock times."""
        node_s = np.cumsum(np.concatenate(([self._node_s], span)))[1:]  # one by one, as _accept adds them
        self._node_s = float(node_s[-1])
        self.clock_map.observe_together(node_s, now)
        self.stats.frames_ok += len(rows)
        self._last, self._last_host = node_frame.frame_of(rows[-1].tolist()), now
        return node_s

    def _columns(self, rows: np.ndarray, t: np.ndarray, now: float) -> NodeBlock:
        """Samples of accepted frames: resistance, CVD temperature and sensor status per channel."""
        ohm = rows[:, _F["r1_mohm"]:_F["r2_mohm"] + 1] / 1000.0
        c1, c2 = self.coefficients
        deg = cvd.temperature(ohm, c1) if c1 == c2 else np.column_stack(
            [cvd.temperature(ohm[:, 0], c1), cvd.temperature(ohm[:, 1], c2)])
        status = _sensor_status(rows, ohm, deg, self.short_ohm)
        if status.any():  # values only where the status allows them
            ohm = np.where((status == _OK) | (status == _RANGE), ohm, np.nan)
            deg = np.where(status == _OK, deg, np.nan)
        return NodeBlock(rows[:, _F["seq"]], rows[:, _F["node_time_ms"]], now, t, ohm, deg, status,
                         rows[:, _F["supply_mv"]], rows[:, _F["rssi_dbm"]], rows[:, _F["lqi"]], rows[:, _F["flags"]])


@njit(cache=True, nogil=True)
def _plainly_consecutive(rows: np.ndarray, last_seq: int, last_ms: int, period_s: float,
                         dropout_s: float) -> tuple[np.ndarray, np.ndarray, bool]:  # pragma: no cover - compiled
    """Per frame (rows in node_frame.FIELDS order; the first after a frame `last_seq`, `last_ms`): whether it follows
    the frame before plainly (seq + 1, no full wrap, no reset flag, node clock forward by at most `dropout_s`), and
    the node clock's step to it in s; and whether all do."""
    n = rows.shape[0]
    plain, span = np.empty(n, dtype=np.bool_), np.empty(n)
    prev_seq, prev_ms = last_seq, last_ms
    for i in range(n):
        seq, t_ms = rows[i, 2], rows[i, 3]
        node_dt = (t_ms - prev_ms) & 0xFFFFFFFF
        span[i] = node_dt / 1000
        plain[i] = (((seq - prev_seq) & 0xFFFF) == 1 and rows[i, 1] & node_frame.NODE_RESET == 0
                    and node_dt < 1 << 31 and span[i] <= dropout_s
                    and np.round((node_dt / (1000 * period_s) - 1) / 65536) <= 0)
        prev_seq, prev_ms = seq, t_ms
    return plain, span, bool(np.all(plain))


@njit(cache=True, nogil=True)
def _sensor_status(rows: np.ndarray, ohm: np.ndarray, deg: np.ndarray,
                   short_ohm: float) -> np.ndarray:  # pragma: no cover - compiled
    """SENSOR_STATUSES index per frame and channel: the node's open/short/fault flags first, then NO_VALUE (fault),
    a resistance below `short_ohm` (short), a temperature outside the CVD range (range)."""
    status = np.empty((rows.shape[0], 2), dtype=np.int64)
    for i in range(rows.shape[0]):
        flags = rows[i, 1]
        for ch in range(2):
            if flags & (node_frame.CH1_OPEN if ch == 0 else node_frame.CH2_OPEN):
                status[i, ch] = _OPEN
            elif flags & (node_frame.CH1_SHORT if ch == 0 else node_frame.CH2_SHORT):
                status[i, ch] = _SHORT
            elif flags & node_frame.ADC_FAULT or rows[i, 4 + ch] == node_frame.NO_VALUE:
                status[i, ch] = _FAULT
            elif ohm[i, ch] < short_ohm:
                status[i, ch] = _SHORT
            else:
                status[i, ch] = _OK if cvd.T_MIN_C <= deg[i, ch] <= cvd.T_MAX_C else _RANGE
    return status
