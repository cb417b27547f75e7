"""Bench controllers on CAN (drive motor, clutch actuator, load machine): set-points out, actual values in.

The driver works on logical signal names (drivers/can_signals.py) so a vendor DBC plus a mapping replaces
ours. Every received frame keeps the time it was measured: the interface's time stamp (`msg.timestamp`)
mapped onto the run clock (`timestamps="interface"`, drivers/timebase.py), taken as it is where the bus
already stamps on the run clock (`"run"`, the simulated bench), or the receive time where the interface
gives none (`"receive"`). `poll()` = `send_due()` (every cyclic command frame, PC heartbeat and, while
active, emergency stop that fell due since the last call, at its DBC cycle) + `receive()` (every waiting
frame, none dropped, decoded and watched: silent = a watched message not seen within `silent_cycles` cycle
times; faulted = fault code ≠ 0 or fault state; alive counter not +1). The waiting frames are taken as one
array (drivers/can_frames.py) and decoded, watched and logged per message id in bulk, with the same results
as frame by frame; `receive_blocks()` hands them out as columns per message, `receive()` as one CanSample
per frame. Frames with an unknown id or a wrong DLC are counted, never decoded. With a `log` (a python-can
Listener such as `can.Logger("run.blf")`; a BLF writer is fed in bulk, drivers/can_log.py) every frame sent
and received is logged, sorted by time at each `receive()`, in the bus's time base; a log that cannot be
written raises CanLogError.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import can
import cantools
import numpy as np
from numba import njit

from drivers import can_codec, can_frames, can_log, timebase
from drivers import can_signals as sig
from drivers.can_codec import CodecTable, MessageCodec, compile_codecs, decode_row, encode_rows
from drivers.can_frames import (ERROR, EXTENDED, FRAME, REMOTE, RX, drain, frames_from_messages, join, make_frames, pick,
                                in_time_order, send_all)
from drivers.can_log import log_frames
from drivers.errors import CanBusError, CanConfigError, CanLogError
from drivers.timebase import ClockMap

EventKind = Literal["silent", "back", "fault", "fault_cleared", "alive_error", "estop", "estop_released"]
TimestampSource = Literal["interface", "run", "receive"]
LOG_SYNC_S = 1.0  # the log file is flushed to the OS this often
MAX_CATCH_UP_S = 1.0  # a cyclic frame more than this late is skipped, not sent in a burst
_STANDARD_IDS = 1 << 11
# why a frame is not decoded (_classify_decode): its id is not one we receive, its length is wrong, it is an error or
# remote frame, it is our own frame echoed by the interface, or its message's codec refused the payload
UNKNOWN_ID, BAD_LENGTH, ERROR_FRAME, OWN_FRAME, DECODE_ERROR = -1, -2, -3, -4, -5
# the columns of _RxTable.meta, one row per received message
LENGTH, COMPILED, ALIVE_COL, ALIVE_MODULO, FAULT_COL, STATE_COL, OWNER = range(7)


@dataclass(frozen=True, slots=True)
class CanSample:
    """One decoded frame: run-clock time it was received by the interface, logical signal → physical value."""

    t: float
    controller: str
    message: str
    values: dict[str, float]


@dataclass(frozen=True, slots=True)
class CanBlock:
    """The frames of one message taken by one `receive_blocks()`, as columns, in the order received."""

    controller: str
    message: str
    index: np.ndarray  # each frame's position among all frames of that receive (arrival order across messages)
    t: np.ndarray  # run-clock time each frame was received by the interface
    # (frames, signals) physical values, C-ordered (compiled consumers see one layout, so compile once, whatever
    # the number of frames); column j holds logical signal keys[j]
    matrix: np.ndarray
    keys: tuple[str, ...]
    # per frame: its alive counter was the previous one + 1 (a stopped, repeated or jumping counter is a frame of a
    # controller not known to be alive: its values are no fresh reading); None: all were
    alive_ok: np.ndarray | None = None

    @property
    def values(self) -> dict[str, np.ndarray]:
        """Logical signal → its column."""
        return {key: self.matrix[:, j] for j, key in enumerate(self.keys)}

    def columns(self, keys: "tuple[str, ...] | list[str]") -> np.ndarray:
        """The (frames, len(keys)) values of `keys`, in that order."""
        return self.matrix.take([self.keys.index(key) for key in keys], axis=1)


@dataclass(frozen=True, slots=True)
class ControllerEvent:
    """Something the watchdog noticed about one controller (or an emergency stop seen on the bus), run time."""

    t: float
    controller: str
    kind: EventKind
    detail: str = ""


@dataclass(slots=True)
class CanStats:
    """Counters of received and sent frames."""

    frames_ok: int = 0
    unknown_id: int = 0
    bad_dlc: int = 0
    decode_errors: int = 0
    error_frames: int = 0
    alive_errors: int = 0
    sent: int = 0
    send_errors: int = 0
    late_skipped: int = 0


@dataclass(frozen=True, slots=True)
class _Rx:
    """How to decode and watch one received message."""

    codec: MessageCodec
    controller: str
    timeout_s: float | None
    alive_key: str | None
    alive_modulo: int
    fault_key: str | None
    state_key: str | None


@dataclass(frozen=True, slots=True)
class _Tx:
    """A message the PC sends: its codec, alive key and cycle time (0: sent only when a set-point changes)."""

    codec: MessageCodec
    alive_key: str | None
    alive_modulo: int
    cycle_s: float


class _RxTable:
    """The received messages as arrays for the compiled paths: id → slot, codec table, watched columns, state."""

    def __init__(self, rx: list[_Rx], ids: list[tuple[int, bool]], now: float) -> None:
        self.rx = rx
        self.codecs = CodecTable([r.codec for r in rx])
        self.standard = np.full(_STANDARD_IDS, UNKNOWN_ID, dtype=np.int64)  # 11-bit id → slot
        extended = sorted((ident, slot) for slot, (ident, is_extended) in enumerate(ids) if is_extended)
        self.extended_ids = np.array([ident for ident, _ in extended], dtype=np.int64)  # sorted, for a binary search
        self.extended_slots = np.array([slot for _, slot in extended], dtype=np.int64)
        for slot, (ident, is_extended) in enumerate(ids):
            if not is_extended:
                self.standard[ident] = slot
        self.controllers = sorted({r.controller for r in rx})
        self.meta = np.array([[r.codec.length, compiled, self._column(r, r.alive_key), max(r.alive_modulo, 1),
                               self._column(r, r.fault_key), self._column(r, r.state_key),
                               self.controllers.index(r.controller)]
                              for r, compiled in zip(rx, self.codecs.compiled.tolist())], dtype=np.int64)
        self.alive_col, self.fault_col, self.state_col = self.meta[:, ALIVE_COL], self.meta[:, FAULT_COL], \
            self.meta[:, STATE_COL]
        self.fallback = not self.codecs.compiled.all()  # some message is decoded row by row in Python
        self.key_columns = [[j for j, key in enumerate(r.codec.columns) if key is not None] for r in rx]
        self.keys = [tuple(r.codec.columns[j] for j in at) for r, at in zip(rx, self.key_columns)]
        # each message's keyed columns as a slice where they come first and in order (a view, no copy)
        self.key_slices = [slice(0, len(at)) if at == list(range(len(at))) else at for at in self.key_columns]
        self.alive = np.full(len(rx), -1, dtype=np.int64)  # last alive counter per slot (-1: none yet)
        self.faulted = np.zeros(len(self.controllers), dtype=bool)  # per controller
        self.last = np.full((len(rx), self.codecs.width), np.nan)  # each message's newest values
        self.seen = np.zeros(len(rx), dtype=bool)  # whether `last` holds a frame's values yet
        self.last_seen = np.full(len(rx), now)  # each message's newest frame time (at first: when the bench opened)

    @staticmethod
    def _column(rx: _Rx, key: str | None) -> int:
        """The value-matrix column of the signal `key` of a message (-1: the message has none)."""
        return -1 if key is None else rx.codec.columns.index(key)


class _TxTable:
    """The messages the PC sends as arrays for the compiled send: codec table, ids, lengths, each one's current values
    (by codec column, alive counters included) and cyclic schedule (the next frame of slot m falls due at
    origin[m] + cycles[m] × cycle[m]; `cyclic` says which slots repeat now)."""

    def __init__(self, tx: list[_Tx], now: float) -> None:
        self.codecs = CodecTable([t.codec for t in tx])
        columns = [tuple(t.codec.columns) for t in tx]
        self.column_of = {key: (m, j) for m, cols in enumerate(columns) for j, key in enumerate(cols) if key is not None}
        self.frame_id = np.array([t.codec.message.frame_id for t in tx], dtype=np.int64)
        self.length = np.array([t.codec.length for t in tx], dtype=np.int64)
        self.extended = np.array([t.codec.message.is_extended_frame for t in tx], dtype=bool)
        self.values = np.zeros((len(tx), self.codecs.width))
        self.alive_col = np.array([-1 if t.alive_key is None else cols.index(t.alive_key)
                                   for t, cols in zip(tx, columns)], dtype=np.int64)
        self.alive_modulo = np.array([max(t.alive_modulo, 1) for t in tx], dtype=np.int64)
        self.cycle = np.array([t.cycle_s for t in tx])
        self.origin = np.full(len(tx), now)
        self.cycles = np.zeros(len(tx), dtype=np.int64)
        self.cyclic = self.cycle > 0
        # each message's frame with everything but time stamp and data (make_frames' flags, length, channel)
        self.template = make_frames(np.zeros(len(tx)), self.frame_id,
                                    np.zeros((len(tx), self.codecs.payload_bytes), dtype=np.uint8), self.length,
                                    extended=self.extended, rx=False)


class CanBench:
    """Talks to the three bench controllers over any python-can bus."""

    def __init__(self, bus: can.BusABC, *, dbc: str | Path = sig.BENCH_DBC,
                 signals: Mapping[str, tuple[str, str]] = sig.BENCH_SIGNALS,
                 clock: Callable[[], float] = time.monotonic, silent_cycles: float = 5,
                 idle_rpm: float = 800.0, fault_state: int = sig.STATE_FAULT, listen_only: bool = False,
                 timestamps: TimestampSource = "interface", log: can.Listener | None = None) -> None:
        if timestamps not in ("interface", "run", "receive"):
            raise CanConfigError(f"timestamps: 'interface', 'run' or 'receive', got {timestamps!r}")
        self.bus, self.clock, self.idle_rpm, self.fault_state = bus, clock, idle_rpm, fault_state
        self.listen_only, self.timestamps, self.log = listen_only, timestamps, log
        self.clock_map = ClockMap()
        try:
            self.db = cantools.database.load_file(str(dbc))
        except (OSError, ValueError, cantools.database.Error) as exc:
            raise CanConfigError(f"{dbc}: not a DBC cantools can load ({type(exc).__name__})") from exc
        self.stats = CanStats()
        self.estop_active = False
        self._events: list[ControllerEvent] = []
        self._silent: dict[str, str] = {}
        self._to_log: list[np.ndarray] = []  # FRAME arrays sent and received, in order
        self._log_synced = -math.inf
        now = clock()
        received, sent = self._compile(signals, silent_cycles)
        self._rx_table = _RxTable(list(received.values()), list(received), now)
        self._tx_table = _TxTable(sent, now)
        if "estop.request" in self._tx_table.column_of:
            self._tx_table.cyclic[self._estop_slot] = False  # repeated only while an emergency stop is active

    @classmethod
    def from_config(cls, config: Mapping[str, Any], **kwargs: Any) -> "CanBench":
        """Build the bus from a python-can config, e.g. {"interface": "socketcan", "channel": "can0"}."""
        try:
            bus = can.Bus(**config)
        except (can.CanError, ValueError, ImportError, OSError) as exc:  # no such interface, channel or driver
            raise CanBusError(f"cannot open the CAN bus {dict(config)}: {exc}") from exc
        return cls(bus, **kwargs)

    # -- set-points --------------------------------------------------------------------------------
    def set_drive_speed(self, rpm: float) -> None:
        """Drive motor (engine side) speed set-point in rpm; enables the drive."""
        self._set({"drive.speed_setpoint": rpm, "drive.enable": 1})

    def set_clutch_torque(self, nm: float) -> None:
        """Clutch actuator torque set-point in N·m (clutch closed as far as needed); enables the actuator."""
        self._set({"clutch.torque_setpoint": nm, "clutch.open_request": 0, "clutch.enable": 1})

    def open_clutch(self) -> None:
        """Open the clutch fully (torque set-point 0, open request)."""
        self._set({"clutch.torque_setpoint": 0.0, "clutch.open_request": 1, "clutch.enable": 1})

    def set_load_torque(self, nm: float) -> None:
        """Load machine torque set-point in N·m; enables the load machine."""
        self._set({"load.torque_setpoint": nm, "load.enable": 1})

    def safe_state(self, drive_rpm: float | None = None, load_nm: float = 0.0) -> None:
        """Clutch open with zero torque, load torque `load_nm` (0), drive at `drive_rpm` (idle speed); sent at once."""
        self._set({"clutch.torque_setpoint": 0.0, "clutch.open_request": 1, "load.torque_setpoint": load_nm,
                   "drive.speed_setpoint": self.idle_rpm if drive_rpm is None else drive_rpm})

    def emergency_stop(self, source: int = sig.ESTOP_SOURCE_PC) -> None:
        """Send the emergency stop now and repeat it every cycle until `release_emergency_stop()`."""
        table, m = self._tx_table, self._estop_slot
        self.estop_active = True
        table.origin[m], table.cycles[m] = self.clock() + table.cycle[m], 0
        table.cyclic[m] = table.cycle[m] > 0
        self._set({"estop.request": 1, "estop.source": source})

    def release_emergency_stop(self) -> None:
        """Send one emergency-stop release and stop repeating it."""
        self._set({"estop.request": 0})
        self.estop_active = False
        self._tx_table.cyclic[self._estop_slot] = False

    @property
    def _estop_slot(self) -> int:
        """The emergency-stop message's slot among those the PC sends (KeyError if the DBC has none)."""
        return self._tx_table.column_of["estop.request"][0]

    # -- the bus -----------------------------------------------------------------------------------
    def poll(self) -> list[CanSample]:
        """`send_due()`, then `receive()`."""
        self.send_due()
        return self.receive()

    def send_due(self) -> None:
        """Send every cyclic frame that fell due up to now, each stamped with its due time (not listen-only); a frame
        more than MAX_CATCH_UP_S late is skipped."""
        if self.listen_only:
            return
        table = self._tx_table
        which, stamps, skipped = _due_cyclic(self.clock(), table.origin, table.cycles, table.cycle, table.cyclic,
                                             MAX_CATCH_UP_S)
        self.stats.late_skipped += skipped
        self._send(which, stamps)

    def receive(self) -> list[CanSample]:
        """Every waiting frame at its own time, decoded and watched, one CanSample per frame in arrival order."""
        return _samples(self.receive_blocks())

    def receive_blocks(self) -> list[CanBlock]:
        """Every waiting frame at its own time, decoded and watched, as columns per message; then the watchdog."""
        now = self.clock()
        try:
            frames = drain(self.bus)
        except can.CanError as exc:  # the interface itself failed (bus-off, adapter gone)
            raise CanBusError(f"receiving: {exc}") from exc
        if self.log is not None and len(frames):
            self._to_log.append(frames)
        blocks = self._take(frames, self._frame_times(frames, now))
        self._watch(now)
        self._flush_log()
        return blocks

    def handle(self, msg: can.Message, t: float) -> CanSample | None:
        """Decode and watch one received frame measured at run time `t`; None (and a counter) if not decodable."""
        samples = _samples(self._take(frames_from_messages([msg]), np.array([t])))
        return samples[0] if samples else None

    def pop_events(self) -> list[ControllerEvent]:
        """Controller events since the last call, oldest first."""
        events, self._events = self._events, []
        return events

    def close(self) -> None:
        """Shut the bus down and stop the log (it stays readable)."""
        try:
            self._flush_log()
            self.bus.shutdown()
        finally:
            if self.log is not None:
                log, self.log = self.log, None
                log.stop()

    # -- internals ---------------------------------------------------------------------------------
    def _frame_times(self, frames: np.ndarray, now: float) -> np.ndarray:
        """Run time of each frame. Interface stamps: the whole batch maps the clocks first (its fastest frame shows
        the offset best; all frames arrive at `now`, so observing the latest stamp is observing every one)."""
        stamps = frames["timestamp"]
        if self.timestamps == "run":  # a copy: the field is a strided view, which compiled code types apart
            return stamps.copy()
        if self.timestamps == "interface" and len(stamps):
            stamped = stamps != 0
            if stamped.any():
                self.clock_map.observe(float(stamps[stamped].max()), now)
                return np.where(stamped, np.minimum(self.clock_map.to_run(stamps), now), now)
        return np.full(len(stamps), now)

    def _take(self, frames: np.ndarray, t: np.ndarray) -> list[CanBlock]:
        """Decode and watch received frames (run times `t`): all messages in one pass, then a block per message.

        Our own frames echoed by the interface (not `is_rx`) are logged, not decoded.
        """
        stats, table = self.stats, self._rx_table
        slot = np.empty(len(frames), dtype=np.int64)
        values = np.empty((len(frames), table.codecs.width))
        _classify_decode(frames, table.standard, table.extended_ids, table.extended_slots, table.meta,
                         table.codecs.bits, table.codecs.linear, slot, values)
        if table.fallback:
            self._decode_in_python(frames, slot, values)
        order, starts, values, t, alive_wrong, alive_before, fault_change, counts = _watch(
            slot, values, t, table.meta, table.alive, float(self.fault_state), table.faulted, table.last,
            table.last_seen)
        flagged, unknown_id, bad_dlc, error_frames, _, decode_errors = counts.tolist()
        stats.unknown_id += unknown_id
        stats.bad_dlc += bad_dlc
        stats.error_frames += error_frames
        stats.decode_errors += decode_errors
        if not len(order):
            return []
        stats.frames_ok += len(order)
        events = []  # (arrival position, check, event): in the order the frames arrived, as frame by frame
        if flagged:
            events = self._frame_events(order, slot.take(order), values, t, alive_wrong, alive_before, fault_change)
        bounds = starts.tolist()
        blocks = []
        for m, rx in enumerate(table.rx):
            a, b = bounds[m], bounds[m + 1]
            if b == a:
                continue
            table.seen[m] = True
            block = CanBlock(rx.controller, rx.codec.message.name, order[a:b], t[a:b],
                             np.ascontiguousarray(values[a:b, table.key_slices[m]]), table.keys[m], ~alive_wrong[a:b])
            if rx.controller == "estop":
                events += self._estop_events(block)
            blocks.append(block)
        self._events += [event for *_, event in sorted(events, key=lambda e: e[:2])]
        return blocks

    def _decode_in_python(self, frames: np.ndarray, slot: np.ndarray, values: np.ndarray) -> None:
        """The frames of messages the compiled pass leaves to cantools (multiplexed, float, > 8 bytes)."""
        table = self._rx_table
        known = np.flatnonzero(slot >= 0)
        rows = known[table.meta[slot.take(known), COMPILED] == 0]
        if not len(rows):
            return
        decoded, valid = table.codecs.decode(slot.take(rows), frames["data"].take(rows, axis=0))
        values[rows] = decoded
        slot[rows[~valid]] = DECODE_ERROR

    def _compile(self, signals: Mapping[str, tuple[str, str]],
                 silent_cycles: float) -> tuple[dict[tuple[int, bool], _Rx], list[_Tx]]:
        rx: dict[tuple[int, bool], _Rx] = {}
        tx: list[_Tx] = []
        for name, codec in compile_codecs(self.db, signals).items():
            message, keys = codec.message, {key: signal for signal, key in codec.names.items()}
            alive = next((k for k in keys if k.endswith("alive")), None)
            modulo = 1 << message.get_signal_by_name(keys[alive]).length if alive else 0
            cycle_s = (message.cycle_time or 0) / 1000
            controller = next(iter(keys)).split(".")[0]
            sent_by_pc = all(k in sig.TX_KEYS for k in keys)
            if sent_by_pc:
                tx.append(_Tx(codec, alive, modulo, cycle_s))
            if controller == "estop" or not sent_by_pc:
                timeout = cycle_s * silent_cycles if cycle_s and controller != "estop" else None
                fault, state = f"{controller}.fault_code", f"{controller}.state"
                rx[(message.frame_id, message.is_extended_frame)] = _Rx(
                    codec, controller, timeout, alive, modulo, fault if fault in keys else None,
                    state if state in keys else None)
        return rx, tx

    def _set(self, updates: Mapping[str, float]) -> None:
        if self.listen_only:
            raise CanConfigError("CanBench was opened listen-only; it sends nothing")
        table, touched = self._tx_table, {}
        for key, value in updates.items():
            m, j = table.column_of[key]
            table.values[m, j] = value
            touched[m] = None
        self._send(np.array(list(touched), dtype=np.int64), np.full(len(touched), self.clock()))

    def _send(self, which: np.ndarray, stamps: np.ndarray) -> None:
        """One frame of message slot which[i] at run time stamps[i] each, with the message's values and its alive
        counter one on per frame: encoded in one pass, sent as one array (drivers/can_frames.py: one python-can message
        per frame on a bus without bulk sending), the frames that went out logged."""
        if not len(which):
            return
        table, codecs = self._tx_table, self._tx_table.codecs
        frames, rows = _next_frames(which, stamps, table.values, table.alive_col, table.alive_modulo, table.template,
                                    codecs.bits, codecs.linear, codecs.compiled)
        if not codecs.compiled.all():  # messages the compiled loop cannot encode
            frames["data"][:, :codecs.payload_bytes] = codecs.encode(which, rows)
        if self.timestamps == "interface" and not math.isnan(self.clock_map.offset):
            frames["timestamp"] -= self.clock_map.offset  # in the bus's time base, as logged (ClockMap.to_device)
        sent = send_all(self.bus, frames)
        count = int(np.count_nonzero(sent))
        self.stats.sent += count
        self.stats.send_errors += len(frames) - count
        if self.log is not None and count:
            self._to_log.append(frames if count == len(frames) else pick(frames, np.flatnonzero(sent)))

    def _flush_log(self) -> None:
        if not self._to_log or self.log is None:
            return
        frames, self._to_log = _in_time_order(self._to_log), []
        try:
            log_frames(self.log, frames)
            now = self.clock()
            if now - self._log_synced >= LOG_SYNC_S:  # written containers leave the process: a kill keeps them
                self._log_synced = now
                file = getattr(self.log, "file", None)
                if file is not None:
                    file.flush()
        except Exception as exc:  # noqa: BLE001 - any writer failure (OSError, ValueError on a closed file)
            log, self.log = self.log, None
            try:
                log.stop()
            except Exception:  # noqa: BLE001 - the log is already broken; the run stops on the error below
                pass
            raise CanLogError(f"CAN log cannot be written: {type(exc).__name__}: {exc}") from exc

    def _frame_events(self, rows: np.ndarray, slot: np.ndarray, values: np.ndarray, t: np.ndarray,
                      alive_wrong: np.ndarray, alive_before: np.ndarray,
                      fault_change: np.ndarray) -> list[tuple[int, int, ControllerEvent]]:
        """Alive-counter (check 0) and fault (check 1) events `_watch` flagged, with each frame's arrival position."""
        table, events = self._rx_table, []
        for i in np.flatnonzero(alive_wrong | (fault_change != 0)).tolist():
            rx, m, row = table.rx[slot[i]], slot[i], int(rows[i])
            if alive_wrong[i]:
                self.stats.alive_errors += 1
                alive = int(values[i, table.alive_col[m]])
                events.append((row, 0, ControllerEvent(float(t[i]), rx.controller, "alive_error",
                                                       f"{rx.codec.message.name}: {alive_before[i]} → {alive}")))
            if fault_change[i]:
                code = int(values[i, table.fault_col[m]]) if table.fault_col[m] >= 0 else 0
                state = "None" if table.state_col[m] < 0 else format(values[i, table.state_col[m]], "g")
                events.append((row, 1, ControllerEvent(float(t[i]), rx.controller,
                                                       "fault" if fault_change[i] > 0 else "fault_cleared",
                                                       f"state {state}, code {code}")))
        return events

    def _estop_events(self, block: CanBlock) -> list[tuple[int, int, ControllerEvent]]:
        """An emergency stop (or its release) seen on the bus, per frame (check 1), with its arrival position."""
        values = block.values
        sources = values.get("estop.source", np.full(len(block.t), np.nan)).tolist()
        return [(row, 1, ControllerEvent(t, "estop", "estop" if request else "estop_released", f"source {source:g}"))
                for row, t, request, source in zip(block.index.tolist(), block.t.tolist(),
                                                   values["estop.request"].tolist(), sources)]

    def _watch(self, now: float) -> None:
        overdue: dict[str, str] = {}
        for rx, last_seen in zip(self._rx_table.rx, self._rx_table.last_seen.tolist()):
            if rx.timeout_s is not None and now - last_seen > rx.timeout_s:
                overdue.setdefault(rx.controller, rx.codec.message.name)
        for controller in self._rx_table.controllers:
            was, now_silent = controller in self._silent, controller in overdue
            if now_silent and not was:
                self._silent[controller] = overdue[controller]
                self._event(now, controller, "silent", f"no {overdue[controller]} for > {self._timeout_of(overdue[controller])} s")
            elif was and not now_silent:
                del self._silent[controller]
                self._event(now, controller, "back")

    def _timeout_of(self, message: str) -> float | None:
        return next(rx.timeout_s for rx in self._rx_table.rx if rx.codec.message.name == message)

    def _event(self, t: float, controller: str, kind: EventKind, detail: str = "") -> None:
        self._events.append(ControllerEvent(t, controller, kind, detail))

    @property
    def silent(self) -> dict[str, str]:
        """Controllers currently silent → the overdue message."""
        return dict(self._silent)

    @property
    def latest(self) -> dict[str, float]:
        """Each received signal's newest value (logical key → physical value), for the signals seen so far."""
        table, latest = self._rx_table, {}
        for keys, at, row, seen in zip(table.keys, table.key_columns, table.last.tolist(), table.seen.tolist()):
            if seen:
                latest.update(zip(keys, [row[j] for j in at]))
        return latest

    @property
    def faulted(self) -> set[str]:
        """Controllers currently reporting a fault."""
        return {c for c, f in zip(self._rx_table.controllers, self._rx_table.faulted.tolist()) if f}


def _in_time_order(parts: list[np.ndarray]) -> np.ndarray:
    """FRAME arrays sent and received as one FRAME array, sorted by time (ties as given)."""
    return in_time_order(join(parts))


def _samples(blocks: list[CanBlock]) -> list[CanSample]:
    """One CanSample per frame of `blocks`, in the order received."""
    numbered = [(i, CanSample(t, b.controller, b.message, dict(zip(b.keys, row))))
                for b in blocks for i, t, row in zip(b.index.tolist(), b.t.tolist(), b.matrix.tolist())]
    numbered.sort(key=lambda pair: pair[0])
    return [sample for _, sample in numbered]


@njit(cache=True, nogil=True)
def _classify_decode(frames: np.ndarray, standard: np.ndarray, extended_ids: np.ndarray, extended_slots: np.ndarray,
                     meta: np.ndarray, bits: np.ndarray, linear: np.ndarray, slot: np.ndarray,
                     values: np.ndarray) -> None:  # pragma: no cover - compiled
    """Per FRAME record its message's slot, or why it is not decoded (UNKNOWN_ID, BAD_LENGTH, ERROR_FRAME,
    OWN_FRAME); the values of the frames of compiled messages (can_codec.decode_row), NaN elsewhere."""
    values[:] = np.nan
    payload = np.empty(8, dtype=np.uint8)  # decode_row's one argument type (other kernels pass rows of a 2-D array)
    for i in range(frames.shape[0]):
        frame = frames[i]
        f, ident = frame.flags, frame.arbitration_id
        if not f & RX:
            m = OWN_FRAME
        elif f & (ERROR | REMOTE):
            m = ERROR_FRAME
        elif f & EXTENDED:
            lo, hi = 0, extended_ids.shape[0]  # binary search (np.searchsorted compiles for a second longer)
            while lo < hi:
                mid = (lo + hi) // 2
                if extended_ids[mid] < ident:
                    lo = mid + 1
                else:
                    hi = mid
            m = extended_slots[lo] if lo < extended_ids.shape[0] and extended_ids[lo] == ident else UNKNOWN_ID
        else:
            m = standard[ident] if ident < _STANDARD_IDS else UNKNOWN_ID
        if m >= 0 and frame.length != meta[m, LENGTH]:
            m = BAD_LENGTH
        slot[i] = m
        if m >= 0 and meta[m, COMPILED]:
            for b in range(8):
                payload[b] = frame.data[b]
            decode_row(payload, m, bits, linear, values[i])


@njit(cache=True, nogil=True)
def _watch(slot: np.ndarray, values: np.ndarray, t: np.ndarray, meta: np.ndarray, alive: np.ndarray,
           fault_state: float, faulted: np.ndarray, last: np.ndarray,
           last_seen: np.ndarray) -> tuple:  # pragma: no cover - compiled
    """Decoded frames (slot ≥ 0) grouped by message (stable), watched frame by frame in that order.

    Returns the order (positions of the decoded frames), each slot's start in it (slots + 1 bounds), their values
    and times in that order, and per position: alive counter not the previous + 1 (and the previous), fault state
    changed (+1 faulted, -1 cleared); and counts: index 0 the frames flagged so, index -reason the frames a reason
    left undecoded. Updates per slot `alive`, `last` (newest values) and `last_seen` (newest
    time), and `faulted` per controller (meta OWNER of each slot).
    """
    n, slots = slot.shape[0], meta.shape[0]
    starts = np.zeros(slots + 1, dtype=np.int64)
    counts = np.zeros(1 - DECODE_ERROR, dtype=np.int64)
    for i in range(n):
        if slot[i] >= 0:
            starts[slot[i] + 1] += 1
        else:
            counts[-slot[i]] += 1
    for m in range(slots):
        starts[m + 1] += starts[m]
    order = np.empty(starts[slots], dtype=np.int64)
    fill = starts[:-1].copy()
    for i in range(n):
        if slot[i] >= 0:
            order[fill[slot[i]]] = i
            fill[slot[i]] += 1
    k_all = order.shape[0]
    grouped, times = np.empty((k_all, values.shape[1])), np.empty(k_all)
    alive_wrong = np.zeros(k_all, dtype=np.bool_)
    alive_before = np.full(k_all, -1, dtype=np.int64)
    fault_change = np.zeros(k_all, dtype=np.int8)
    for k in range(k_all):
        i = order[k]
        m = slot[i]
        times[k] = t[i]
        for j in range(values.shape[1]):  # element by element: a row assignment compiles numba's shape-mismatch error
            grouped[k, j] = last[m, j] = values[i, j]
        last_seen[m] = max(last_seen[m], t[i])
        alive_col, fault_col, state_col = meta[m, ALIVE_COL], meta[m, FAULT_COL], meta[m, STATE_COL]
        if alive_col >= 0:
            counter = np.int64(values[i, alive_col])
            if alive[m] >= 0 and counter != (alive[m] + 1) % meta[m, ALIVE_MODULO]:
                alive_wrong[k] = True
                alive_before[k] = alive[m]
            alive[m] = counter
        if fault_col >= 0 or state_col >= 0:
            code = np.int64(values[i, fault_col]) if fault_col >= 0 else 0
            now_faulted = code != 0 or (state_col >= 0 and values[i, state_col] == fault_state)
            if now_faulted != faulted[meta[m, OWNER]]:
                fault_change[k] = 1 if now_faulted else -1
                faulted[meta[m, OWNER]] = now_faulted
        if alive_wrong[k] or fault_change[k]:
            counts[0] += 1
    return order, starts, grouped, times, alive_wrong, alive_before, fault_change, counts


@njit(cache=True, nogil=True)
def _due_cyclic(now: float, origin: np.ndarray, cycles: np.ndarray, cycle: np.ndarray, cyclic: np.ndarray,
                max_catch_up: float) -> tuple:  # pragma: no cover - compiled
    """The cyclic frames due up to `now` (+1 ns): per slot in slot order, each at its due time (at most `now`);
    frames more than `max_catch_up` late are skipped. Advances `cycles`; returns (slots, times, skipped)."""
    skipped, count = 0, 0
    for m in range(origin.shape[0]):
        if not cyclic[m]:
            continue
        late = now - (origin[m] + cycles[m] * cycle[m])
        if late > max_catch_up:
            skip = np.int64(late // cycle[m])
            cycles[m] += skip
            skipped += skip
        k = 0
        while origin[m] + (cycles[m] + k) * cycle[m] <= now + 1e-9:
            k += 1
        count += k
    which, times = np.empty(count, dtype=np.int64), np.empty(count)
    at = 0
    for m in range(origin.shape[0]):
        if not cyclic[m]:
            continue
        while origin[m] + cycles[m] * cycle[m] <= now + 1e-9:
            which[at], times[at] = m, min(origin[m] + cycles[m] * cycle[m], now)
            cycles[m] += 1
            at += 1
    return which, times, skipped


@njit(cache=True, nogil=True)
def _next_frames(which: np.ndarray, stamps: np.ndarray, values: np.ndarray, alive_col: np.ndarray,
                 alive_modulo: np.ndarray, template: np.ndarray, bits: np.ndarray, linear: np.ndarray,
                 compiled: np.ndarray) -> tuple:  # pragma: no cover - compiled
    """One frame of each slot in `which` at `stamps`, in order: its message's template with the values (alive counter
    one on first) encoded by can_codec.encode_rows; returns (frames, values per frame)."""
    rows = np.empty((which.shape[0], values.shape[1]))
    for k in range(which.shape[0]):
        m = which[k]
        if alive_col[m] >= 0:
            values[m, alive_col[m]] = (np.int64(values[m, alive_col[m]]) + 1) % alive_modulo[m]
        for j in range(values.shape[1]):  # element by element: a row assignment compiles numba's shape-mismatch error
            rows[k, j] = values[m, j]
    payloads = np.zeros((which.shape[0], template[0].data.shape[0]), dtype=np.uint8)
    encode_rows(which, rows, bits, linear, compiled, payloads)
    frames = np.empty(which.shape[0], template.dtype)
    for k in range(which.shape[0]):
        frames[k] = template[which[k]]
        frames[k].timestamp = stamps[k]
        data = frames[k].data
        for b in range(payloads.shape[1]):
            data[b] = payloads[k, b]
    return frames, rows


def prime() -> None:
    """Compile (or load from numba's cache) every kernel a CanBench calls, before a control loop uses one: a
    first-call compile there stalls the loop for seconds while the bench holds its last commands. Each kernel
    once on zero frames and zero-length arrays of the dtypes the driver's tables hold (nothing sent, logged or
    changed)."""
    can_codec.prime()
    can_frames.prime()
    can_log.prime()
    timebase.prime()
    frames, none, index = np.zeros(0, FRAME), np.zeros(0), np.zeros(0, np.int64)
    meta, bits, linear = np.zeros((0, OWNER + 1), np.int64), np.zeros((0, 4, 0), np.uint64), np.zeros((0, 4, 0))
    values = np.zeros((0, 0))
    _classify_decode(frames, index, index, index, meta, bits, linear, index, values)
    _watch(index, values, none, meta, index, 0.0, np.zeros(0, bool), values, none)
    _due_cyclic(0.0, none, index, none, np.zeros(0, bool), MAX_CATCH_UP_S)
    _next_frames(index, none, values, index, index, np.zeros(1, FRAME), bits, linear, np.zeros(0, bool))
