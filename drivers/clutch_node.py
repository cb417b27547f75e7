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

from drivers import cvd, node_frame, timebase
from drivers.errors import ConnectionLost, DriverConfigError
from drivers.timebase import ClockMap, observe_into

SensorStatus = Literal["ok", "open", "short", "range", "fault"]
SENSOR_STATUSES: tuple[SensorStatus, ...] = ("ok", "open", "short", "range", "fault")  # NodeBlock.status indexes this
_OK, _OPEN, _SHORT, _RANGE, _FAULT = range(len(SENSOR_STATUSES))
_MAX_CHUNK = 4 * node_frame.ENCODED_LEN
ERROR_WINDOW_S = 1.0
MAX_POLL_BYTES = 1 << 16  # one poll takes at most this much (0.7 s of the 921,600-baud link): the loop goes on
CorruptCounter = Literal["crc_errors", "malformed", "resyncs"]
TABLE_COLUMNS = ("seq", "node_time_s", "temperature_1_c", "temperature_2_c", "resistance_1_ohm", "resistance_2_ohm",
                 "status_1", "status_2", "supply_v", "rssi_dbm", "lqi", "flags")  # NodeBlock.table's; status: index
_T1, _R1, _S1 = (TABLE_COLUMNS.index(name) for name in ("temperature_1_c", "resistance_1_ohm", "status_1"))
_NO_ROWS = np.zeros((0, len(node_frame.FIELDS)), dtype=np.int64)
_NO_TABLE, _NO_T = np.zeros((0, len(TABLE_COLUMNS))), np.zeros(0)
_F = {name: j for j, name in enumerate(node_frame.FIELDS)}
_PERIOD, _DROPOUT, _SHORT_OHM, _COEF = range(4)  # the gateway's settings array; CVD coefficients (4 per channel) last
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
    """The samples of one read, one row per accepted frame in the order received: the frames' fields (`rows`), their
    measurement times and the samples as one float table (TABLE_COLUMNS: NodeSample's values, per channel NaN where
    NodeSample has None, the status as an index into SENSOR_STATUSES); NodeSample's fields as columns too."""

    rows: np.ndarray  # (n, 9) the frames' fields, node_frame.FIELDS order
    t_host: float  # run-clock time the gateway received the frames
    t: np.ndarray  # run-clock time the node measured each (its own clock mapped onto the run clock)
    table: np.ndarray  # (n, 12) TABLE_COLUMNS; the block's own (fresh every read)
    newest_measured: int  # row of the newest sample with a temperature, -1 if none has one
    t_measured: float  # the latest `t` of the samples with a temperature (NaN if none)

    def __len__(self) -> int:
        return len(self.rows)

    seq = property(lambda self: self.rows[:, _F["seq"]])
    node_time_ms = property(lambda self: self.rows[:, _F["node_time_ms"]])
    resistance_ohm = property(lambda self: self.table[:, _R1:_R1 + 2], doc="(n, 2) Ω")
    temperature_c = property(lambda self: self.table[:, _T1:_T1 + 2], doc="(n, 2) °C")
    status = property(lambda self: self.table[:, _S1:_S1 + 2].astype(np.int64), doc="(n, 2) SENSOR_STATUSES index")
    supply_mv = property(lambda self: self.rows[:, _F["supply_mv"]])
    rssi_dbm = property(lambda self: self.rows[:, _F["rssi_dbm"]])
    lqi = property(lambda self: self.rows[:, _F["lqi"]])
    flags = property(lambda self: self.rows[:, _F["flags"]])

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

    kind: Literal["dropout_start", "dropout_end", "node_reset", "frame_errors", "clock_remapped"]
    t_host: float
    last_seq: int | None
    span_s: float | None = None
    lost_frames: int = 0
    crc_errors: int = 0
    malformed: int = 0
    resyncs: int = 0
    offset_s: float | None = None  # clock_remapped: the node clock's new offset to the run clock (s)


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
        self.port, self.period_s, self.clock, self.short_ohm = port, period_s, clock, short_ohm  # fixed once made
        self.dropout_s = dropout_periods * period_s
        self.coefficients = tuple(coefficients)
        self._settings = np.array([period_s, self.dropout_s, short_ohm]
                                  + [v for c in self.coefficients for v in (c.r0, c.a, c.b, c.c)])
        self.stats = GatewayStats()
        self._events: list[LinkEvent] = []
        self._buf = b""
        self._synced = False
        self._last_seq: int | None = None  # the newest accepted frame's seq and node clock (ms), None before one
        self._last_ms = 0
        self._last_host = clock()
        self.clock_map = ClockMap()  # the node's clock → run clock (anew after a node reboot)
        self._remaps = 0  # the map's re-maps already reported
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
        try:  # everything already there: pyserial's socket:// says 1 byte waiting whenever any is, so a port that
            received = bytearray()  # says 1 is asked again (bounded); one that counts is read once a poll
            waiting = self.port.in_waiting
            while waiting:
                received += self.port.read(waiting)
                waiting = self.port.in_waiting if waiting == 1 and len(received) < MAX_POLL_BYTES else 0
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"gateway port: {exc}") from exc
        data = bytes(received)
        block = self.feed_block(data) if data else self._block(_NO_ROWS, self.clock())
        self.check_silence()
        if self.clock_map.remaps > self._remaps:  # the node clock drifted beyond the allowance or jumped: said so
            self._events.append(LinkEvent("clock_remapped", block.t_host, self._last_seq, offset_s=self.clock_map.offset))
        self._remaps = self.clock_map.remaps  # a new map after a reboot counts from 0
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
        """`feed`, the samples as one block of columns: every delimited chunk decoded in one compiled pass (the usual
        read, frames only and each plainly after the one before, decoded and taken in one compiled call)."""
        now = self.clock()
        buf = self._buf + data
        if self._last_seq is not None and not self._in_dropout:
            rows, table, t, node_s, newest, t_measured, rest = _read_plain(
                buf, self._last_seq, self._last_ms, self._node_s, self.clock_map.state, now, self._settings)
            if rest >= 0:  # taken as `_accept` takes them one by one (nothing lost, no event)
                self._keep_rest(buf[rest:], now)
                n = len(rows)
                if n:
                    self._synced, self._node_s = True, node_s
                    self.stats.frames_ok += n
                    self._last_seq, self._last_ms, self._last_host = int(rows[-1, 2]), int(rows[-1, 3]), now
                self._report_errors(now)
                return NodeBlock(rows, now, t, table, newest, t_measured)
        rows, status, rest_bytes = node_frame.decode_stream(buf)
        self._keep_rest(rest_bytes, now)
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

    def _keep_rest(self, rest: bytes, now: float) -> None:
        """Keep the unterminated rest of the stream for the next read; one longer than a frame can be is dropped (a
        resync)."""
        self._buf = rest
        if len(rest) > _MAX_CHUNK:
            self._buf, self._synced = b"", False
            self._count_corrupt("resyncs", now)

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
            "frame_errors", now, self._last_seq, now - window.t0,
            window.crc_errors + window.malformed, window.crc_errors, window.malformed, window.resyncs))
        self._errors = None

    def _start_dropout(self, t: float) -> None:
        """The one place a drop-out begins, so that every `dropout_end` has exactly one `dropout_start`."""
        self._in_dropout = True
        self.stats.dropouts += 1
        self._events.append(LinkEvent("dropout_start", t, self._last_seq))

    def _accept(self, row: list[int], now: float) -> bool:
        """Sequence bookkeeping; False for a duplicate. Emits reset and drop-out events.

        A gap longer than the drop-out limit that fell between two polls was never seen as silence by
        `check_silence` (the host polls slower than the limit, e.g. 1 s ticks against 0.25 s): its
        `dropout_start` is emitted here, dated when the silence passed the limit, before its end.
        """
        last, stats = self._last_seq, self.stats
        seq, t_ms, flags = row[_F["seq"]], row[_F["node_time_ms"]], row[_F["flags"]]
        host_span = now - self._last_host
        lost, span, reset = 0, host_span, False
        if last is not None:
            seq_gap = (seq - last) & 0xFFFF
            node_dt = (t_ms - self._last_ms) & 0xFFFFFFFF
            if seq_gap == 0 and node_dt == 0:
                stats.duplicates += 1
                return False
            reset = bool(flags & node_frame.NODE_RESET) or node_dt >= 1 << 31
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
            self._node_s, self.clock_map = t_ms / 1000, ClockMap()
        if reset:
            self._events.append(LinkEvent("node_reset", now, last, host_span, lost))
        if self._in_dropout:
            self._events.append(LinkEvent("dropout_end", now, last, span, lost))
            self._in_dropout = False
        stats.frames_ok += 1
        self._last_seq, self._last_ms, self._last_host = seq, t_ms, now
        return True

    def _block(self, rows: np.ndarray, now: float) -> NodeBlock:
        """The accepted frames among `rows` (node_frame.FIELDS order, as received) as samples, each through `_accept`
        (the reads that are not plainly consecutive frames: the usual read is `_read_plain`)."""
        n = len(rows)
        if not n:
            return NodeBlock(_NO_ROWS, now, _NO_T, _NO_TABLE, -1, math.nan)
        keep, t = np.zeros(n, dtype=bool), np.empty(n)
        accepted: list[tuple[int, float, ClockMap]] = []  # row, node clock time, the node clock's map it belongs to
        for i, row in enumerate(rows.tolist()):
            if self._accept(row, now):
                keep[i] = True
                accepted.append((i, self._node_s, self.clock_map))
        for clock_map in {id(m): m for _, _, m in accepted}.values():  # each map observes its frames of this read
            node_times = [node_s for _, node_s, m in accepted if m is clock_map]  # together, as `_read_plain` does:
            observe_into(clock_map.state, min(node_times), max(node_times), now)  # the newest tells a drifting clock
        for i, node_s, clock_map in accepted:  # each with its map as the whole read left it
            t[i] = min(clock_map.to_run(node_s), now)
        rows, t = rows[keep], t[keep]
        return NodeBlock(rows, now, t, *_table(rows, t, self._settings))


@njit(cache=True, nogil=True)
def _read_plain(src: bytes, last_seq: int, last_ms: int, node_s: float, clock: np.ndarray, now: float,
                settings: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int, float,
                                               int]:  # pragma: no cover - compiled
    """The usual read in one call: every delimited chunk of `src` decoded and, if all are frames, `_plain_block` of
    them, with where the unterminated rest begins; rest -1 (and nothing changed) if any chunk is not a frame or any
    frame does not follow plainly."""
    rows, status, rest = node_frame.decode_chunks(np.frombuffer(src, dtype=np.uint8))
    plain = True
    for k in range(status.shape[0]):
        plain = plain and status[k] == node_frame.OK
    if plain and rows.shape[0]:
        table, t, node_s, newest, t_measured = _plain_block(rows, last_seq, last_ms, node_s, clock, now, settings)
        if t.shape[0] == rows.shape[0]:
            return rows, table, t, node_s, newest, t_measured, rest
    elif plain:
        return rows, np.empty((0, len(TABLE_COLUMNS))), np.empty(0), node_s, -1, np.nan, rest
    return rows, np.empty((0, len(TABLE_COLUMNS))), np.empty(0), node_s, -1, np.nan, -1


@njit(cache=True, nogil=True)
def _plain_block(rows: np.ndarray, last_seq: int, last_ms: int, node_s: float, clock: np.ndarray, now: float,
                 settings: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int, float]:  # pragma: no cover - compiled
    """The usual read in one pass: if every frame of `rows` follows the one before plainly (the first after frame
    `last_seq`, `last_ms`), their node clock times counted on from `node_s` one by one, the clock map `clock`
    updated with them (`observe_into` of frames received together: the offset of taking them one by one), their run
    times and `_table`; else nothing changed and no rows."""
    span, all_plain = _plainly_consecutive(rows, last_seq, last_ms, settings[_PERIOD], settings[_DROPOUT])
    if not all_plain:
        return np.empty((0, len(TABLE_COLUMNS))), np.empty(0), node_s, -1, np.nan
    n = rows.shape[0]
    times = np.empty(n)
    for i in range(n):
        node_s += span[i]
        times[i] = node_s
    offset = observe_into(clock, times[0], node_s, now)
    for i in range(n):
        times[i] = min(times[i] + offset, now)
    table, newest, t_measured = _table(rows, times, settings)
    return table, times, node_s, newest, t_measured


@njit(cache=True, nogil=True)
def _table(rows: np.ndarray, t: np.ndarray, settings: np.ndarray) -> tuple[np.ndarray, int, float]:  # pragma: no cover
    """NodeBlock's table of accepted frames measured at `t` (resistance, CVD temperature and sensor status per
    channel, values only where the status allows them), the newest row with a temperature and the latest `t` of
    those."""
    n = rows.shape[0]
    table = np.empty((n, len(TABLE_COLUMNS)))
    newest, t_measured = -1, np.nan
    for i in range(n):
        flags = rows[i, 1]
        for ch in range(2):
            c = _COEF + 4 * ch
            ohm = rows[i, 4 + ch] / 1000.0
            deg = cvd.temperature_of(ohm, settings[c], settings[c + 1], settings[c + 2], settings[c + 3])
            status = _sensor_status(flags, rows[i, 4 + ch], ohm, deg, ch, settings[_SHORT_OHM])
            table[i, _T1 + ch] = deg if status == _OK else np.nan
            table[i, _R1 + ch] = ohm if status == _OK or status == _RANGE else np.nan
            table[i, _S1 + ch] = status
            if status == _OK:
                t_measured = t[i] if newest < 0 else max(t_measured, t[i])
                newest = i
        table[i, 0], table[i, 1] = rows[i, 2], rows[i, 3] / 1000.0
        table[i, 8], table[i, 9], table[i, 10], table[i, 11] = rows[i, 6] / 1000.0, rows[i, 7], rows[i, 8], flags
    return table, newest, t_measured


@njit(cache=True, nogil=True)
def _plainly_consecutive(rows: np.ndarray, last_seq: int, last_ms: int, period_s: float,
                         dropout_s: float) -> tuple[np.ndarray, bool]:  # pragma: no cover - compiled
    """The node clock's step to each frame in s (rows in node_frame.FIELDS order; the first after a frame `last_seq`,
    `last_ms`), and whether every frame follows the one before plainly (seq + 1, no full wrap, no reset flag, node
    clock forward by at most `dropout_s`)."""
    n = rows.shape[0]
    span = np.empty(n)
    all_plain = True
    prev_seq, prev_ms = last_seq, last_ms
    for i in range(n):
        seq, t_ms = rows[i, 2], rows[i, 3]
        node_dt = (t_ms - prev_ms) & 0xFFFFFFFF
        span[i] = node_dt / 1000
        all_plain = all_plain and (((seq - prev_seq) & 0xFFFF) == 1 and rows[i, 1] & node_frame.NODE_RESET == 0
                                   and node_dt < 1 << 31 and span[i] <= dropout_s
                                   and np.round((node_dt / (1000 * period_s) - 1) / 65536) <= 0)
        prev_seq, prev_ms = seq, t_ms
    return span, all_plain


@njit(cache=True, nogil=True)
def _sensor_status(flags: int, r_mohm: int, ohm: float, deg: float, ch: int,
                   short_ohm: float) -> int:  # pragma: no cover - compiled
    """SENSOR_STATUSES index of channel `ch` of a frame: the node's open/short/fault flags first, then NO_VALUE (fault),
    a resistance below `short_ohm` (short), a temperature outside the CVD range (range)."""
    if flags & (node_frame.CH1_OPEN if ch == 0 else node_frame.CH2_OPEN):
        return _OPEN
    if flags & (node_frame.CH1_SHORT if ch == 0 else node_frame.CH2_SHORT):
        return _SHORT
    if flags & node_frame.ADC_FAULT or r_mohm == node_frame.NO_VALUE:
        return _FAULT
    if ohm < short_ohm:
        return _SHORT
    return _OK if cvd.T_MIN_C <= deg <= cvd.T_MAX_C else _RANGE


def prime() -> None:
    """Compile (or load from numba's cache) every kernel a gateway's read calls, before a control loop polls it (a
    first-call compile there stalls the loop for seconds): each once on zero frames and a scratch clock map."""
    node_frame.prime()
    timebase.prime()
    cvd.prime()
    settings = np.zeros(_COEF + 8)
    _read_plain(b"", 0, 0, 0.0, ClockMap().state, 0.0, settings)
    _table(_NO_ROWS, _NO_T, settings)
