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
from numba import njit

from drivers import can_signals as sig
from drivers.can_codec import CodecTable, compile_codecs
from drivers.can_frames import EXTENDED, drain, make_frames, pick, send_all
from sim_bench.emulators.drivetrain import DrivetrainActuals, DrivetrainProvider, FirstOrderDrivetrain


COMMAND_LATENCY_S = 1e-6  # a command takes effect this long after the newest frame already sent, at the earliest
_ACTUAL_OF = {"drive.speed": "drive_speed_rpm", "drive.torque": "drive_torque_nm", "clutch.torque": "clutch_torque_nm",
              "clutch.position": "clutch_position_mm", "clutch.clamp_state": "clamp_state",
              "load.torque": "load_torque_nm", "load.speed": "load_speed_rpm"}  # signal → DrivetrainActuals field
_ACTUALS = list(DrivetrainActuals.__dataclass_fields__)


@dataclass(slots=True)
class _Controller:
    """Emulated state of one controller."""

    name: str
    setpoints: dict[str, float] = field(default_factory=dict)
    last_cmd: float | None = None
    injected_fault: int = 0
    silent: bool = False
    alive_frozen: bool = False
    alive: dict[str, int] = field(default_factory=dict)
    sent_cycles: dict[str, int] = field(default_factory=dict)  # frames due so far per message (sent or silenced)


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
        self._modulo = {key: 1 << self.db.get_message_by_name(m).get_signal_by_name(s).length
                        for key, (m, s) in signals.items() if key.endswith("alive")}
        self.stats = EmulatorStats()
        self.estop = False
        self.controllers = {name: _Controller(name) for name in sig.CONTROLLERS}
        received = ("drive.cmd_alive", "clutch.cmd_alive", "load.cmd_alive", "estop.request", "pc.hb_alive")
        self._rx = {self._codec_of[key].message.frame_id: (i, key.split(".")[0], self._codec_of[key])
                    for i, key in enumerate(received)}  # frame id → (slot in the command table, owner, codec)
        self._rx_table = CodecTable([self._codec_of[key] for key in received])
        # per command slot the (column, key) of the values that are set-points (not the alive counter)
        self._setpoint_columns = [[(j, c) for j, c in enumerate(self._codec_of[key].columns)
                                   if c is not None and not c.endswith("alive")] for key in received]
        self._taken: dict[str, list[float] | None] = {name: None for name in self.controllers}  # set-points last taken
        self.origin = clock()
        self._t = self.origin  # frames due before this instant have been sent
        for ctrl in self.controllers.values():
            for key in (f"{ctrl.name}.alive", f"{ctrl.name}.hb_alive"):
                ctrl.sent_cycles[key] = 1  # the first frame one cycle after start-up (a time stamp of 0.0 means "unset")
                ctrl.alive[key] = 0
        # every message the controllers send (status and heartbeat, keyed by its alive counter) as one codec table
        sent = [f"{name}.{alive}" for name in sig.CONTROLLERS for alive in ("alive", "hb_alive")]
        self._slot = {key: i for i, key in enumerate(sent)}
        self._table = CodecTable([self._codec_of[key] for key in sent])
        self._frame_id = np.array([self._codec_of[key].message.frame_id for key in sent])
        self._extended = np.array([self._codec_of[key].message.is_extended_frame for key in sent])
        self._length = np.array([self._codec_of[key].length for key in sent])
        self._cycle = {key: self._codec_of[key].message.cycle_time / 1000 for key in sent}
        # where each column of each sent message comes from: an actual value (index into _ACTUALS), else -1
        columns = [self._codec_of[key].columns for key in sent]
        self._source = np.array([[_ACTUALS.index(_ACTUAL_OF[c]) if c in _ACTUAL_OF else -1 for c in cols]
                                 + [-1] * (self._table.width - len(cols)) for cols in columns])
        self._alive_col = np.array([cols.index(key) for cols, key in zip(columns, sent)])
        self._column = [{c: j for j, c in enumerate(cols) if c is not None} for cols in columns]

    # -- fault hooks ---------------------------------------------------------------------------------
    def silence(self, controller: str, on: bool = True) -> None:
        """The controller stops (or resumes) sending anything."""
        self.controllers[controller].silent = on

    def set_fault(self, controller: str, code: int) -> None:
        """From now on the controller reports fault `code` (state Fault) and holds its safe set-point until cleared."""
        self._emit_until(self.clock(), inclusive=False)
        self.controllers[controller].injected_fault = code
        self._apply(self.clock())

    def clear_fault(self, controller: str) -> None:
        """Remove an injected fault (from now on)."""
        self.set_fault(controller, 0)

    def freeze_alive(self, controller: str, on: bool = True) -> None:
        """The controller's alive counters stop counting (a hung task still sending old frames)."""
        self.controllers[controller].alive_frozen = on

    def send_raw(self, arbitration_id: int, data: bytes, is_extended_id: bool = False) -> None:
        """Put an arbitrary frame on the bus (wrong DLC, unknown id, ...)."""
        self.bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=is_extended_id))

    # -- running -----------------------------------------------------------------------------------------
    def poll(self) -> None:
        """Apply the waiting commands at their times and send every frame due up to now, in time order.

        A command that changes nothing (same set-points, controller running) only refreshes the command
        time-out; the frames are then sent in whole segments between the commands that change something.
        """
        now = self.clock()
        for owner, stamp, slot, row in self._commands():
            # a command acts after the last frame already reported (a frame measured when it was sent is gone)
            t = min(max(stamp or now, self._t + COMMAND_LATENCY_S), now)
            ctrl = self.controllers.get(owner)
            setpoints = [row[j] for j, _ in self._setpoint_columns[slot]]
            if ctrl is not None and setpoints == self._taken[owner] and not self._timed_out(ctrl, t):
                ctrl.last_cmd = t  # the same set-points again: only the command time-out starts anew
                continue
            values = {c: row[j] for j, c in enumerate(self._rx_table.codecs[slot].columns) if c is not None}
            if self._changes(owner, values, t):
                self._emit_until(t, inclusive=False)
                self._take(owner, values, t)
                self._apply(t)
            elif ctrl is not None:
                ctrl.last_cmd = t
            if ctrl is not None:
                self._taken[owner] = setpoints
        self._emit_until(now, inclusive=True)

    def state(self, controller: str, t: float | None = None) -> tuple[int, int]:
        """(state, fault code) the controller reports at `t` (default: now)."""
        t = self.clock() if t is None else t
        ctrl = self.controllers[controller]
        code = ctrl.injected_fault or (sig.FAULT_COMMAND_TIMEOUT if self._timed_out(ctrl, t) else 0)
        if self.estop:
            return sig.STATE_ESTOP, code
        if code:
            return sig.STATE_FAULT, code
        return (sig.STATE_RUNNING if ctrl.setpoints.get(f"{controller}.enable") else sig.STATE_READY), 0

    # -- internals -----------------------------------------------------------------------------------
    def _deadline(self, ctrl: _Controller) -> float | None:
        """When an enabled controller times out without a further command (None: it cannot)."""
        if ctrl.last_cmd is None or not ctrl.setpoints.get(f"{ctrl.name}.enable"):
            return None
        return ctrl.last_cmd + self.command_timeout_s

    def _timed_out(self, ctrl: _Controller, t: float) -> bool:
        deadline = self._deadline(ctrl)
        return deadline is not None and t > deadline + 1e-9

    def _commands(self) -> list[tuple[str, float, int, list[float]]]:
        """The waiting command frames in time order (stable), decoded in one pass: (owner, time stamp, command slot,
        values by codec column); frames with an unknown id, a wrong length or id kind are counted as malformed."""
        frames = drain(self.bus)
        if not len(frames):
            return []
        frames = pick(frames, np.argsort(frames["timestamp"], kind="stable"))
        known = []
        for i, (ident, flags, length) in enumerate(zip(frames["arbitration_id"].tolist(), frames["flags"].tolist(),
                                                       frames["length"].tolist())):
            slot, owner, codec = self._rx.get(ident, (-1, None, None))
            if codec is None or length != codec.length or bool(flags & EXTENDED) != codec.message.is_extended_frame:
                self.stats.malformed += 1
                continue
            known.append((i, slot, owner))
        if not known:
            return []
        rows = np.array([i for i, _, _ in known])
        which = np.array([slot for _, slot, _ in known])
        values, valid = self._rx_table.decode(which, frames["data"].take(rows, axis=0))
        self.stats.commands_ok += int(np.count_nonzero(valid))
        self.stats.malformed += len(known) - int(np.count_nonzero(valid))
        return [(owner, stamp, slot, row) for (_, slot, owner), stamp, row, ok
                in zip(known, frames["timestamp"].take(rows).tolist(), values.tolist(), valid.tolist()) if ok]

    def _changes(self, owner: str, values: Mapping[str, float], t: float) -> bool:
        """Whether a command changes what the controllers do (set-points, time-out ending, emergency stop)."""
        if owner == "pc":
            return False
        if owner == "estop":
            return bool(values["estop.request"]) != self.estop
        ctrl = self.controllers[owner]
        if ctrl.last_cmd is None or self._timed_out(ctrl, t):
            return True
        return any(ctrl.setpoints.get(k) != v for k, v in values.items() if not k.endswith("alive"))

    def _take(self, owner: str, values: Mapping[str, float], t: float) -> None:
        if owner == "estop":
            self.estop = bool(values["estop.request"])
            return
        ctrl = self.controllers[owner]
        ctrl.setpoints.update(values)
        ctrl.last_cmd = t

    def _apply(self, t: float) -> None:
        """Set-points the controllers hold from `t` on (safe ones where not running)."""
        self.provider.advance(t)
        sp = {name: (c.setpoints if self.state(name, t)[0] == sig.STATE_RUNNING else {})
              for name, c in self.controllers.items()}
        self.provider.set_drive_speed(sp["drive"].get("drive.speed_setpoint", 0.0))
        self.provider.set_clutch(sp["clutch"].get("clutch.torque_setpoint", 0.0),
                                 bool(sp["clutch"].get("clutch.open_request", 1)))
        self.provider.set_load_torque(sp["load"].get("load.torque_setpoint", 0.0))

    def _emit_until(self, t_end: float, inclusive: bool) -> None:
        """Send the frames due in [self._t, t_end) (or up to t_end inclusive), cut where a controller times out."""
        while True:
            deadlines = (self._deadline(c) for c in self.controllers.values())
            cut = min((d for d in deadlines if d is not None and self._t < d < t_end), default=None)
            if cut is None:
                self._emit_segment(t_end, inclusive)
                return
            self._emit_segment(cut, True)
            self._apply(cut + 1e-9)

    def _emit_segment(self, t_end: float, inclusive: bool) -> None:
        """Frames due in [self._t, t_end] with the controllers' states and set-points as they are now."""
        eps = 1e-9 if inclusive else -1e-9
        plan: list[tuple[_Controller, str, int, int]] = []  # controller, message (its alive key), cycles k0 ≤ k < k1
        for ctrl in self.controllers.values():
            for key in (f"{ctrl.name}.alive", f"{ctrl.name}.hb_alive"):
                k0 = ctrl.sent_cycles[key]
                k1 = math.floor((t_end + eps - self.origin) / self._cycle[key]) + 1
                if k1 > k0:
                    if not ctrl.silent:
                        plan.append((ctrl, key, k0, k1))
                    ctrl.sent_cycles[key] = k1
        self._t = max(self._t, t_end)
        if not plan:
            return
        slots = np.array([self._slot[key] for _, key, _, _ in plan])
        item, local, stamps, times, row = _due_frames(
            np.array([k0 for _, _, k0, _ in plan]), np.array([k1 - k0 for _, _, k0, k1 in plan]),
            np.array([self._cycle[key] for _, key, _, _ in plan]), self._frame_id.take(slots), self.origin)
        actuals = self.provider.actuals_at(times)
        constant = np.zeros((len(plan), self._table.width))  # state, fault code, heartbeat state per message
        start, frozen, modulo = [], [], []
        for p, (ctrl, key, k0, k1) in enumerate(plan):
            state, code = self.state(ctrl.name, self.origin + k0 * self._cycle[key])
            column = self._column[self._slot[key]]
            for name, value in ((f"{ctrl.name}.state", state), (f"{ctrl.name}.fault_code", code),
                                (f"{ctrl.name}.hb_state", state)):
                if name in column:
                    constant[p, column[name]] = value
            start.append(ctrl.alive[key])
            frozen.append(ctrl.alive_frozen)
            modulo.append(self._modulo[key])
            if not ctrl.alive_frozen:
                ctrl.alive[key] = (ctrl.alive[key] + k1 - k0) % self._modulo[key]
        values = _frame_values(item, local, row, np.array([getattr(actuals, name) for name in _ACTUALS]),
                               self._source.take(slots, axis=0), constant, self._alive_col.take(slots),
                               np.array(start), np.array(frozen), np.array(modulo))
        slot = slots.take(item)
        frames = make_frames(stamps, self._frame_id.take(slot), self._table.encode(slot, values),
                             self._length.take(slot), extended=self._extended.take(slot))
        self.stats.sent += int(np.count_nonzero(send_all(self.bus, frames)))


@njit(cache=True, nogil=True)
def _due_frames(first: np.ndarray, count: np.ndarray, cycle: np.ndarray, frame_id: np.ndarray,
                origin: float) -> tuple:  # pragma: no cover - compiled
    """The frames of messages p = 0.. due at origin + (first[p] + l)·cycle[p], l < count[p], merged in time order
    (ties by frame id): each frame's message p and number l, its time; the distinct times, each frame's among them."""
    n = count.sum()
    item, local = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    stamps, times, row = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    taken = np.zeros(count.shape[0], dtype=np.int64)
    distinct = 0
    for k in range(n):
        best, best_t = -1, 0.0
        for p in range(count.shape[0]):
            if taken[p] < count[p]:
                t = origin + (first[p] + taken[p]) * cycle[p]
                if best < 0 or t < best_t or (t == best_t and frame_id[p] < frame_id[best]):
                    best, best_t = p, t
        item[k], local[k], stamps[k] = best, taken[best], best_t
        taken[best] += 1
        if distinct == 0 or best_t != times[distinct - 1]:
            times[distinct] = best_t
            distinct += 1
        row[k] = distinct - 1
    return item, local, stamps, times[:distinct].copy(), row


@njit(cache=True, nogil=True)
def _frame_values(item: np.ndarray, local: np.ndarray, row: np.ndarray, measured: np.ndarray, source: np.ndarray,
                  constant: np.ndarray, alive_col: np.ndarray, start: np.ndarray, frozen: np.ndarray,
                  modulo: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Each frame's signal values: a measured actual (source ≥ 0, at the frame's time `row`) or its message's
    constant, and the alive counter counting on from `start` (held while frozen)."""
    values = np.empty((item.shape[0], source.shape[1]))
    for k in range(item.shape[0]):
        p = item[k]
        for j in range(source.shape[1]):
            values[k, j] = measured[source[p, j], row[k]] if source[p, j] >= 0 else constant[p, j]
        values[k, alive_col[p]] = start[p] if frozen[p] else (start[p] + 1 + local[k]) % modulo[p]
    return values
