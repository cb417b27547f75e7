"""Emulated bench controllers (drive motor, clutch actuator, load machine) on any python-can bus.

Speaks the frames of drivers/bench.dbc through the same logical signal map as the driver. `poll()` takes the
waiting command frames and, in time order, applies each at its time stamp, then sends every status frame and
heartbeat that fell due up to now at its DBC cycle time, stamped with the instant it fell due and carrying the
drivetrain's actual values at that instant (a controller samples and sends on its own cycle, whenever the PC
reads the bus); the frames of one poll go out as one array of FRAME records (drivers/can_frames.py) onto a bus
that takes arrays (the simulated bus), else one can.Message at a time. A controller that is disabled, faulted,
without commands for `command_timeout_s` (default 3 command cycles; fault 16 while it lasts) or under
emergency stop gets safe set-points (drive 0 rpm, clutch open, load 0 N·m). Fault hooks: `silence`,
`set_fault`, `clear_fault`, `freeze_alive`, `send_raw`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import can
import cantools
import numpy as np
from benchlab.jit import njit

from drivers import can_frames
from drivers import can_signals as sig
from drivers.can_codec import CodecTable, compile_codecs, decode_row, encode_rows
from drivers.can_frames import EXTENDED, FRAME, drain, in_time_order, make_frames, send_all
from sim_bench.emulators.drivetrain import DrivetrainActuals, DrivetrainProvider, FirstOrderDrivetrain


COMMAND_LATENCY_S = 1e-6  # a command takes effect this long after the newest frame already sent, at the earliest
_ACTUAL_OF = {"drive.speed": "drive_speed_rpm", "drive.torque": "drive_torque_nm", "clutch.torque": "clutch_torque_nm",
              "clutch.position": "clutch_position_mm", "clutch.clamp_state": "clamp_state",
              "load.torque": "load_torque_nm", "load.speed": "load_speed_rpm"}  # signal → DrivetrainActuals field
_ACTUALS = list(DrivetrainActuals.__dataclass_fields__)


_ESTOP, _IGNORED = -1, -2  # command owners that are not a controller: the emergency stop; the PC's heartbeat
_STATE, _CODE, _COUNT = range(3)  # rows of _due_frames' per-message status
_STATUS_OF = {"state": _STATE, "hb_state": _STATE, "fault_code": _CODE}  # signal after the controller's name → row
_CYCLES, _ALIVE, _SILENT, _FROZEN = range(4)  # columns of the per-message counters
_ALIVE_COL, _MODULO, _ID, _OWNER = range(4)  # the per-message layout's last columns, after source and status source
_SCALARS = 4
_ITEM, _LOCAL, _ROW = range(3)  # rows of _due_frames' per-frame index
_RX_ID, _RX_LENGTH, _RX_EXTENDED, _RX_CONTROLLER = range(4)  # columns of the command slots' matrix


@dataclass(slots=True)
class _Controller:
    """One controller: its set-points; the rest of its state is row `index` of the emulator's per-controller arrays."""

    name: str
    index: int
    setpoints: dict[str, float] = field(default_factory=dict)


@dataclass(slots=True)
class EmulatorStats:
    """Frames the emulated controllers received and sent."""

    commands_ok: int = 0
    malformed: int = 0
    sent: int = 0


class CanBenchEmulator:
    """The three bench controllers; physics from a `DrivetrainProvider` (default: FirstOrderDrivetrain)."""

    def __init__(self, bus: can.BusABC, provider: DrivetrainProvider | None = None, *,
                 dbc: str | Path = sig.BENCH_DBC, signals: Mapping[str, tuple[str, str]] = sig.BENCH_SIGNALS,
                 clock: Callable[[], float] = time.monotonic, command_timeout_s: float | None = None) -> None:
        self.bus, self.clock = bus, clock
        self.provider = provider or FirstOrderDrivetrain(t0=clock())
        self.db = cantools.database.load_file(str(dbc))
        self.codecs = compile_codecs(self.db, signals)
        self._codec_of = {key: codec for codec in self.codecs.values() for key in codec.names.values()}
        self.command_timeout_s = (command_timeout_s if command_timeout_s is not None
                                  else 3 * self._codec_of["drive.cmd_alive"].message.cycle_time / 1000)
        modulo = {key: 1 << self.db.get_message_by_name(m).get_signal_by_name(s).length
                  for key, (m, s) in signals.items() if key.endswith("alive")}
        self.stats = EmulatorStats()
        self.estop = False
        self.controllers = {name: _Controller(name, i) for i, name in enumerate(sig.CONTROLLERS)}
        # per controller: time of the last command taken (NaN: none yet), enabled, injected fault code, and the
        # command values last taken (NaN: none yet; only the set-point columns count)
        n = len(self.controllers)
        self._last_cmd, self._enabled, self._fault = np.full(n, np.nan), np.zeros(n, dtype=bool), np.zeros(n, np.int64)
        # the command frames: per slot in the command table its frame id, length, id kind and who takes it (columns
        # _RX_ID, _RX_LENGTH, _RX_EXTENDED, _RX_CONTROLLER)
        received = ("drive.cmd_alive", "clutch.cmd_alive", "load.cmd_alive", "estop.request", "pc.hb_alive")
        rx = [self._codec_of[key] for key in received]
        self._rx_table = CodecTable(rx)
        self._rx_all_compiled = bool(self._rx_table.compiled.all())
        self._rx_owner = [key.split(".")[0] for key in received]
        self._rx = np.array([[codec.message.frame_id, codec.length, codec.message.is_extended_frame,
                              self.controllers[o].index if o in self.controllers else _ESTOP if o == "estop"
                              else _IGNORED] for codec, o in zip(rx, self._rx_owner)], dtype=np.int64)
        # per command slot and column: whether the value is a set-point (not the alive counter, not a padding column)
        self._setpoint = np.array([[c is not None and not c.endswith("alive") for c in codec.columns]
                                   + [False] * (self._rx_table.width - len(codec.columns)) for codec in rx])
        self._taken = np.full((n, self._rx_table.width), np.nan)
        self.origin = clock()
        self._t = self.origin  # frames due before this instant have been sent
        # every message the controllers send (status and heartbeat, keyed by its alive counter) as one codec table,
        # and per message: its controller, cycle, frames due so far (sent or silenced; the first one cycle after
        # start-up: a time stamp of 0.0 means "unset"), alive counter, whether silenced or frozen
        sent = [f"{name}.{alive}" for name in sig.CONTROLLERS for alive in ("alive", "hb_alive")]
        codecs = [self._codec_of[key] for key in sent]
        self._table = CodecTable(codecs)
        self._owner = np.array([self.controllers[key.split(".")[0]].index for key in sent])
        self._cycle = np.array([codec.message.cycle_time / 1000 for codec in codecs])
        # the counters in one integer matrix (one argument for the compiled passes), columns _CYCLES, _ALIVE,
        # _SILENT, _FROZEN, read and written through the views below
        self._counters = np.zeros((len(sent), 4), dtype=np.int64)
        self._sent_cycles, self._alive = self._counters[:, _CYCLES], self._counters[:, _ALIVE]
        self._silent, self._frozen = self._counters[:, _SILENT], self._counters[:, _FROZEN]
        self._sent_cycles[:] = 1
        # each message's frame with everything but time stamp and data (make_frames' flags, length, channel)
        self._template = make_frames(np.zeros(len(sent)), np.array([codec.message.frame_id for codec in codecs]),
                                     np.zeros((len(sent), self._table.payload_bytes), dtype=np.uint8),
                                     np.array([codec.length for codec in codecs]),
                                     extended=np.array([codec.message.is_extended_frame for codec in codecs]))
        # where each column of each sent message comes from: an actual value (index into _ACTUALS), else -1; the
        # controller's state or fault code (status row), else -1; then which column is the alive counter, its
        # modulo, the frame id and the controller: one integer matrix (blocks of width, width, _SCALARS columns)
        columns = [list(codec.columns) + [None] * (self._table.width - len(codec.columns)) for codec in codecs]
        source = [[_ACTUALS.index(_ACTUAL_OF[c]) if c in _ACTUAL_OF else -1 for c in cols] for cols in columns]
        status_source = [[_STATUS_OF.get(c.split(".", 1)[1], -1)
                          if c is not None and c.split(".")[0] == key.split(".")[0] else -1
                          for c in cols] for cols, key in zip(columns, sent)]
        scalars = [[cols.index(key), modulo[key], codec.message.frame_id, int(self._owner[p])]
                   for p, (cols, key, codec) in enumerate(zip(columns, sent, codecs))]
        self._layout = np.array([a + b + c for a, b, c in zip(source, status_source, scalars)], dtype=np.int64)
        self._all_compiled = bool(self._table.compiled.all())

    # -- fault hooks ---------------------------------------------------------------------------------
    def silence(self, controller: str, on: bool = True) -> None:
        """The controller stops (or resumes) sending anything."""
        self._silent[self._owner == self.controllers[controller].index] = on

    def set_fault(self, controller: str, code: int) -> None:
        """From now on the controller reports fault `code` (state Fault) and holds its safe set-point until cleared."""
        self._emit_until(self.clock(), inclusive=False)
        self._fault[self.controllers[controller].index] = code
        self._apply(self.clock())

    def clear_fault(self, controller: str) -> None:
        """Remove an injected fault (from now on)."""
        self.set_fault(controller, 0)

    def freeze_alive(self, controller: str, on: bool = True) -> None:
        """The controller's alive counters stop counting (a hung task still sending old frames)."""
        self._frozen[self._owner == self.controllers[controller].index] = on

    def send_raw(self, arbitration_id: int, data: bytes, is_extended_id: bool = False) -> None:
        """Put an arbitrary frame on the bus (wrong DLC, unknown id, ...)."""
        self.bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=is_extended_id))

    # -- running -----------------------------------------------------------------------------------------
    def poll(self) -> None:
        """Apply the waiting commands at their times and send every frame due up to now, in time order.

        A command that changes nothing (same set-points, controller running) only refreshes the command
        time-out (in one compiled pass); the frames are then sent in whole segments between the commands that
        change something.
        """
        now = self.clock()
        frames = in_time_order(drain(self.bus))  # stable: frames of one instant stay in arrival order
        table = self._rx_table
        which, stamps, payloads, values, valid, ok, i = _take_commands(
            frames, self._rx, table.payload_bytes, table.bits, table.linear, table.compiled, self._rx_all_compiled,
            now, self._t + COMMAND_LATENCY_S, self._setpoint, self._taken, self._last_cmd, self._enabled,
            self.command_timeout_s)
        if not self._rx_all_compiled:  # messages the compiled pass cannot decode: all rows again, then refresh
            values, valid = table.decode(which, payloads)
            ok, i = int(np.count_nonzero(valid)), self._refresh(which, stamps, values, valid, 0, now)
        self.stats.commands_ok += ok
        self.stats.malformed += len(frames) - ok
        while i < len(which):
            self._command(int(which[i]), float(stamps[i]), values[i], now)
            i = self._refresh(which, stamps, values, valid, i + 1, now)
        self._emit_until(now, inclusive=True)

    def state(self, controller: str, t: float | None = None) -> tuple[int, int]:
        """(state, fault code) the controller reports at `t` (default: now)."""
        return self._state(self.controllers[controller].index, self.clock() if t is None else t)

    # -- internals -----------------------------------------------------------------------------------
    def _state(self, c: int, t: float) -> tuple[int, int]:
        return _status(t, self._fault[c], self._last_cmd[c], self._enabled[c], self.estop, self.command_timeout_s)

    def _timed_out(self, c: int, t: float) -> bool:
        return _is_timed_out(t, self._last_cmd[c], self._enabled[c], self.command_timeout_s)

    def _refresh(self, which: np.ndarray, stamps: np.ndarray, values: np.ndarray, valid: np.ndarray, start: int,
                 now: float) -> int:
        """`_refresh_commands` from command `start` on: the index of the next command that may change something."""
        return _refresh_commands(which, stamps, values, valid, start, now, self._t + COMMAND_LATENCY_S, self._rx,
                                 self._setpoint, self._taken, self._last_cmd, self._enabled, self.command_timeout_s)

    def _command(self, slot: int, stamp: float, row: np.ndarray, now: float) -> None:
        """Take one command frame that may change something (see `_refresh_commands` for the ones that cannot)."""
        # a command acts after the last frame already reported (a frame measured when it was sent is gone)
        t = min(max(stamp or now, self._t + COMMAND_LATENCY_S), now)
        owner = self._rx_owner[slot]
        values = {c: v for c, v in zip(self._rx_table.codecs[slot].columns, row.tolist()) if c is not None}
        ctrl = self.controllers.get(owner)
        if self._changes(owner, values, t):
            self._emit_until(t, inclusive=False)
            self._take(owner, values, t)
            self._apply(t)
        elif ctrl is not None:
            self._last_cmd[ctrl.index] = t
        if ctrl is not None:
            self._taken[ctrl.index] = row

    def _changes(self, owner: str, values: Mapping[str, float], t: float) -> bool:
        """Whether a command changes what the controllers do (set-points, time-out ending, emergency stop)."""
        if owner == "estop":
            return bool(values["estop.request"]) != self.estop
        ctrl = self.controllers[owner]
        if math.isnan(self._last_cmd[ctrl.index]) or self._timed_out(ctrl.index, t):
            return True
        return any(ctrl.setpoints.get(k) != v for k, v in values.items() if not k.endswith("alive"))

    def _take(self, owner: str, values: Mapping[str, float], t: float) -> None:
        if owner == "estop":
            self.estop = bool(values["estop.request"])
            return
        ctrl = self.controllers[owner]
        ctrl.setpoints.update(values)
        self._last_cmd[ctrl.index] = t
        self._enabled[ctrl.index] = bool(ctrl.setpoints.get(f"{owner}.enable"))

    def _apply(self, t: float) -> None:
        """Set-points the controllers hold from `t` on (safe ones where not running)."""
        self.provider.advance(t)
        sp = {name: (c.setpoints if self._state(c.index, t)[0] == sig.STATE_RUNNING else {})
              for name, c in self.controllers.items()}
        self.provider.set_drive_speed(sp["drive"].get("drive.speed_setpoint", 0.0))
        self.provider.set_clutch(sp["clutch"].get("clutch.torque_setpoint", 0.0),
                                 bool(sp["clutch"].get("clutch.open_request", 1)))
        self.provider.set_load_torque(sp["load"].get("load.torque_setpoint", 0.0))

    def _emit_until(self, t_end: float, inclusive: bool) -> None:
        """Send the frames due in [self._t, t_end) (or up to t_end inclusive), cut where a controller times out."""
        while not math.isnan(cut := self._emit_segment(t_end, inclusive)):
            self._apply(cut)  # timed out from the deadline on: the safe set-points hold from there

    def _emit_segment(self, t_end: float, inclusive: bool) -> float:
        """Frames due in [self._t, t_end] with the controllers' states and set-points as they are now, up to and
        including the first instant a controller times out if that comes first: returns that instant (NaN: none)."""
        index, stamps, times, status, cut = _due_frames(
            self._counters, self._t, t_end, 1e-9 if inclusive else -1e-9, self.origin, self._cycle, self._layout,
            self._fault, self._last_cmd, self._enabled, self.estop, self.command_timeout_s)
        self._t = max(self._t, t_end if math.isnan(cut) else cut)
        if not len(stamps):
            return cut
        frames, values = _frames(index, stamps, self.provider.actuals_matrix(times), self._layout, status,
                                 self._counters, self._template, self._table.bits, self._table.linear,
                                 self._table.compiled)
        if not self._all_compiled:  # messages the compiled loop cannot encode
            frames["data"][:, :self._table.payload_bytes] = self._table.encode(index[_ITEM], values)
        self.stats.sent += int(np.count_nonzero(send_all(self.bus, frames)))
        return cut


@njit(cache=True, nogil=True)
def _is_timed_out(t: float, last_cmd: float, enabled: bool, timeout: float) -> bool:  # pragma: no cover - compiled
    """Whether an enabled controller whose last command came at `last_cmd` (NaN: none) has timed out at `t`: from
    the deadline `last_cmd + timeout` on, the instant `_first_deadline` cuts at included (it applies the safe
    set-points there)."""
    return enabled and not math.isnan(last_cmd) and t >= last_cmd + timeout


@njit(cache=True, nogil=True)
def _status(t: float, fault: int, last_cmd: float, enabled: bool, estop: bool,
            timeout: float) -> tuple:  # pragma: no cover - compiled
    """(state, fault code) a controller reports at `t`: emergency stop, else an injected fault or the command
    time-out, else running while enabled, else ready."""
    code = fault if fault else (sig.FAULT_COMMAND_TIMEOUT if _is_timed_out(t, last_cmd, enabled, timeout) else 0)
    if estop:
        return sig.STATE_ESTOP, code
    if code:
        return sig.STATE_FAULT, code
    return (sig.STATE_RUNNING if enabled else sig.STATE_READY), 0


@njit(cache=True, nogil=True)
def _first_deadline(last_cmd: np.ndarray, enabled: np.ndarray, timeout: float, after: float,
                    before: float) -> float:  # pragma: no cover - compiled
    """The earliest instant strictly between `after` and `before` at which an enabled controller times out without
    a further command (NaN: none)."""
    cut = math.nan
    for c in range(last_cmd.shape[0]):
        if enabled[c] and not math.isnan(last_cmd[c]):
            d = last_cmd[c] + timeout
            if after < d < before and (math.isnan(cut) or d < cut):
                cut = d
    return cut


@njit(cache=True, nogil=True)
def _known_frames(frames: np.ndarray, rx: np.ndarray, width: int) -> tuple:  # pragma: no cover - compiled
    """The FRAME records (in time order) of known command messages (id, length and id kind of a slot of `rx`): each
    one's slot, time stamp and first `width` data bytes."""
    n = frames.shape[0]
    which, stamps = np.empty(n, dtype=np.int64), np.empty(n)
    payloads = np.zeros((n, width), dtype=np.uint8)
    k = 0
    for i in range(n):
        f = frames[i]
        for s in range(rx.shape[0]):
            if (f.arbitration_id == rx[s, _RX_ID] and f.length == rx[s, _RX_LENGTH]
                    and ((f.flags & EXTENDED) != 0) == (rx[s, _RX_EXTENDED] != 0)):
                which[k], stamps[k] = s, f.timestamp
                for b in range(min(width, f.data.shape[0])):
                    payloads[k, b] = f.data[b]
                k += 1
                break
    return which[:k], stamps[:k], payloads[:k]


@njit(cache=True, nogil=True)
def _take_commands(frames: np.ndarray, rx: np.ndarray, width: int, bits: np.ndarray, linear: np.ndarray,
                   compiled: np.ndarray, refresh: bool, now: float, earliest: float, setpoint: np.ndarray,
                   taken: np.ndarray, last_cmd: np.ndarray, enabled: np.ndarray,
                   timeout: float) -> tuple:  # pragma: no cover - compiled
    """The known command frames (`_known_frames`: slot, time stamp, payload) decoded where the codec table compiles
    their message (values, whether decoded, how many; the others are left for CodecTable.decode), and, if
    `refresh`, the commands that only refresh a time-out taken (`_refresh_commands` from 0): returns those and the
    index of the first command left."""
    which, stamps, payloads = _known_frames(frames, rx, width)
    values = np.full((which.shape[0], bits.shape[2]), np.nan)
    valid = np.zeros(which.shape[0], dtype=np.bool_)
    ok = 0
    for i in range(which.shape[0]):
        if compiled[which[i]]:
            decode_row(payloads[i], which[i], bits, linear, values[i])
            valid[i] = True
            ok += 1
    # from command 0 as an int64, not a literal: the one signature `_refresh` calls it with from Python
    first = (_refresh_commands(which, stamps, values, valid, np.int64(0), now, earliest, rx, setpoint, taken, last_cmd,
                               enabled, timeout) if refresh else 0)
    return which, stamps, payloads, values, valid, ok, first


@njit(cache=True, nogil=True)
def _refresh_commands(which: np.ndarray, stamps: np.ndarray, values: np.ndarray, valid: np.ndarray, start: int,
                      now: float, earliest: float, rx: np.ndarray, setpoint: np.ndarray, taken: np.ndarray,
                      last_cmd: np.ndarray, enabled: np.ndarray, timeout: float) -> int:  # pragma: no cover
    """From command `start` on, take the commands that only refresh a controller's time-out (the set-points it last
    took again, not timed out: last_cmd = the command's time) and skip the ones nobody acts on (not decoded, the
    PC's heartbeat); stop at the first other one and return its index (len(which): none left)."""
    for i in range(start, which.shape[0]):
        c = rx[which[i], _RX_CONTROLLER]
        if not valid[i] or c == _IGNORED:
            continue
        if c < 0:
            return i
        t = min(max(stamps[i] if stamps[i] != 0.0 else now, earliest), now)
        if _is_timed_out(t, last_cmd[c], enabled[c], timeout):
            return i
        for j in range(values.shape[1]):
            if setpoint[which[i], j] and not values[i, j] == taken[c, j]:
                return i
        last_cmd[c] = t
    return which.shape[0]


@njit(cache=True, nogil=True)
def _due_frames(counters: np.ndarray, t_start: float, t_end: float, eps: float, origin: float, cycle: np.ndarray,
                layout: np.ndarray, fault: np.ndarray, last_cmd: np.ndarray, enabled: np.ndarray, estop: bool,
                timeout: float) -> tuple:  # pragma: no cover - compiled
    """The frames of messages p falling due at origin + k·cycle[p] from k = counters[p, _CYCLES] up to t_end + eps,
    or up to and including the first instant strictly between t_start and t_end at which a controller times out
    (`_first_deadline`) if there is one, merged in time order (ties by frame id); the cycle counter moves on past
    them (silenced messages' frames too, but they are not returned). Returns per frame (rows _ITEM, _LOCAL, _ROW)
    its message p, its number among p's frames and its time's index among the distinct times; the frames' times;
    the distinct times; per message (rows _STATE, _CODE) the (state, fault code) of its controller at its first
    frame and (row _COUNT) the number of its frames; the time-out instant (NaN: none)."""
    cut = _first_deadline(last_cmd, enabled, timeout, t_start, t_end)
    if not math.isnan(cut):
        t_end, eps = cut, 1e-9
    m, w = counters.shape[0], (layout.shape[1] - _SCALARS) // 2
    status = np.zeros((3, m))
    count = np.zeros(m, dtype=np.int64)
    n = 0  # the frames due: summed here, np.sum's compile is a second kernel's
    for p in range(m):
        k1 = int(np.floor((t_end + eps - origin) / cycle[p])) + 1
        k0 = counters[p, _CYCLES]
        if k1 > k0:
            if not counters[p, _SILENT]:
                count[p] = k1 - k0
                n += k1 - k0
                c = layout[p, 2 * w + _OWNER]
                status[_STATE, p], status[_CODE, p] = _status(origin + k0 * cycle[p], fault[c], last_cmd[c],
                                                              enabled[c], estop, timeout)
            counters[p, _CYCLES] = k1
    index, stamps, times = np.empty((3, n), dtype=np.int64), np.empty(n), np.empty(n)
    taken = np.zeros(m, dtype=np.int64)
    distinct = 0
    for k in range(n):
        best, best_t = -1, 0.0
        for p in range(m):
            if taken[p] < count[p]:
                t = origin + (counters[p, _CYCLES] - count[p] + taken[p]) * cycle[p]
                if best < 0 or t < best_t or (t == best_t and layout[p, 2 * w + _ID] < layout[best, 2 * w + _ID]):
                    best, best_t = p, t
        index[_ITEM, k], index[_LOCAL, k], stamps[k] = best, taken[best], best_t
        taken[best] += 1
        if distinct == 0 or best_t != times[distinct - 1]:
            times[distinct] = best_t
            distinct += 1
        index[_ROW, k] = distinct - 1
    for p in range(m):
        status[_COUNT, p] = count[p]
    return index, stamps, times[:distinct].copy(), status, cut


@njit(cache=True, nogil=True)
def _frames(index: np.ndarray, stamps: np.ndarray, measured: np.ndarray, layout: np.ndarray, status: np.ndarray,
            counters: np.ndarray, template: np.ndarray, bits: np.ndarray, linear: np.ndarray,
            compiled: np.ndarray) -> tuple:  # pragma: no cover - compiled
    """Each frame of `_due_frames`' index, stamps and status as its message's `template` at its time stamp, and its
    signal values by the message's `layout`: a measured actual (DrivetrainActuals row, at the frame's time:
    column index[_ROW] of `measured`), its message's state or fault code, or 0, and the alive counter counting on
    from counters[p, _ALIVE] (held while frozen), encoded by the codec table layout (bits, linear, compiled); the
    alive counters then move on past each message's frames."""
    n, w = stamps.shape[0], (layout.shape[1] - _SCALARS) // 2
    frames = template[index[_ITEM]]
    values = np.empty((n, w))
    for k in range(n):
        p = index[_ITEM, k]
        frames[k].timestamp = stamps[k]
        for j in range(w):
            if layout[p, j] >= 0:
                values[k, j] = measured[layout[p, j], index[_ROW, k]]
            elif layout[p, w + j] >= 0:
                values[k, j] = status[layout[p, w + j], p]
            else:
                values[k, j] = 0.0
        alive, modulo = counters[p, _ALIVE], layout[p, 2 * w + _MODULO]
        counted = alive if counters[p, _FROZEN] else (alive + 1 + index[_LOCAL, k]) % modulo
        values[k, layout[p, 2 * w + _ALIVE_COL]] = counted
    payloads = np.zeros((n, 8), dtype=np.uint8)
    encode_rows(index[_ITEM], values, bits, linear, compiled, payloads)
    for k in range(n):
        for b in range(8):
            frames[k].data[b] = payloads[k, b]
    for p in range(counters.shape[0]):
        if status[_COUNT, p] and not counters[p, _FROZEN]:
            counters[p, _ALIVE] = (counters[p, _ALIVE] + int(status[_COUNT, p])) % layout[p, 2 * w + _MODULO]
    return frames, values


def prime() -> None:
    """Compile (or load from numba's cache) the emulated controllers' kernels for the one signature each is called
    with, before a real-time run: a first-call compile inside it silences the controllers past the driver's limit.
    Each once on zero frames and zero-length arrays of the emulator's dtypes (nothing taken, sent or changed)."""
    can_frames.prime()  # the time-order check of every poll
    frames, none, index, flags = np.zeros(0, FRAME), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool)
    bits, linear, values = np.zeros((0, 4, 0), np.uint64), np.zeros((0, 4, 0)), np.zeros((0, 0))
    rx, setpoint = np.zeros((0, _RX_CONTROLLER + 1), np.int64), np.zeros((0, 0), bool)
    counters, layout = np.zeros((0, _FROZEN + 1), np.int64), np.zeros((0, _SCALARS), np.int64)
    _take_commands(frames, rx, 0, bits, linear, flags, True, 0.0, 0.0, setpoint, values, none, flags, 0.0)
    _refresh_commands(index, none, values, flags, 0, 0.0, 0.0, rx, setpoint, values, none, flags, 0.0)
    _due_frames(counters, 0.0, 0.0, 0.0, 0.0, none, layout, index, none, flags, False, 0.0)
    _frames(np.zeros((_ROW + 1, 0), np.int64), none, np.zeros((len(_ACTUALS), 0)), layout,
            np.zeros((_COUNT + 1, 0)), counters, frames, bits, linear, flags)
    _status(0.0, 0, math.nan, False, False, 0.0)
    _is_timed_out(0.0, math.nan, False, 0.0)
