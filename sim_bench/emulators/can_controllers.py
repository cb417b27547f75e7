"""Emulated bench controllers (drive motor, clutch actuator, load machine) on any python-can bus.

Speaks the frames of drivers/bench.dbc through the same logical signal map as the driver. `poll()` takes the
waiting command frames without blocking, advances the provider to the clock's time and sends each status
frame and heartbeat when its cycle time is due (at most one per poll, no backlog bursts). A controller that
is disabled, faulted, without commands for `command_timeout_s` (fault 16 while it lasts) or under emergency
stop gets safe set-points (drive 0 rpm, clutch open, load 0 N·m). Fault hooks: `silence`, `set_fault`,
`clear_fault`, `freeze_alive`, `send_raw`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import can
import cantools

from drivers import can_signals as sig
from drivers.can_codec import compile_codecs
from sim_bench.emulators.drivetrain import DrivetrainActuals, DrivetrainProvider, FirstOrderDrivetrain


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
    next_due: dict[str, float] = field(default_factory=dict)


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
                 clock: Callable[[], float] = time.monotonic, command_timeout_s: float = 0.1) -> None:
        self.bus, self.clock, self.command_timeout_s = bus, clock, command_timeout_s
        self.provider = provider or FirstOrderDrivetrain(t0=clock())
        self.db = cantools.database.load_file(str(dbc))
        self.codecs = compile_codecs(self.db, signals)
        self._codec_of = {key: codec for codec in self.codecs.values() for key in codec.names.values()}
        self._modulo = {key: 1 << self.db.get_message_by_name(m).get_signal_by_name(s).length
                        for key, (m, s) in signals.items() if key.endswith("alive")}
        self.stats = EmulatorStats()
        self.estop = False
        self.controllers = {name: _Controller(name) for name in sig.CONTROLLERS}
        self._rx = {self._codec_of[key].message.frame_id: (key.split(".")[0], self._codec_of[key])
                    for key in ("drive.cmd_alive", "clutch.cmd_alive", "load.cmd_alive", "estop.request", "pc.hb_alive")}
        now = clock()
        for ctrl in self.controllers.values():
            for key in (f"{ctrl.name}.alive", f"{ctrl.name}.hb_alive"):
                ctrl.next_due[key] = now
                ctrl.alive[key] = 0

    # -- fault hooks ---------------------------------------------------------------------------------
    def silence(self, controller: str, on: bool = True) -> None:
        """The controller stops (or resumes) sending anything."""
        self.controllers[controller].silent = on

    def set_fault(self, controller: str, code: int) -> None:
        """The controller reports fault `code` (state Fault) and goes to its safe set-point until cleared."""
        self.controllers[controller].injected_fault = code

    def clear_fault(self, controller: str) -> None:
        """Remove an injected fault."""
        self.controllers[controller].injected_fault = 0

    def freeze_alive(self, controller: str, on: bool = True) -> None:
        """The controller's alive counters stop counting (a hung task still sending old frames)."""
        self.controllers[controller].alive_frozen = on

    def send_raw(self, arbitration_id: int, data: bytes, is_extended_id: bool = False) -> None:
        """Put an arbitrary frame on the bus (wrong DLC, unknown id, ...)."""
        self.bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=is_extended_id))

    # -- running -----------------------------------------------------------------------------------------
    def poll(self) -> None:
        """Take commands, advance the physics to now, send what is due."""
        while (msg := self.bus.recv(timeout=0)) is not None:
            self._receive(msg)
        now = self.clock()
        self._apply(now)
        self.provider.advance(now)
        actuals = self.provider.actuals()
        for ctrl in self.controllers.values():
            self._send_due(ctrl, actuals, now)

    def state(self, controller: str) -> tuple[int, int]:
        """(state, fault code) the controller reports now."""
        ctrl = self.controllers[controller]
        timed_out = (ctrl.setpoints.get(f"{controller}.enable") and ctrl.last_cmd is not None
                     and self.clock() - ctrl.last_cmd > self.command_timeout_s)
        code = ctrl.injected_fault or (sig.FAULT_COMMAND_TIMEOUT if timed_out else 0)
        if self.estop:
            return sig.STATE_ESTOP, code
        if code:
            return sig.STATE_FAULT, code
        return (sig.STATE_RUNNING if ctrl.setpoints.get(f"{controller}.enable") else sig.STATE_READY), 0

    # -- internals -----------------------------------------------------------------------------------
    def _receive(self, msg: can.Message) -> None:
        owner, codec = self._rx.get(msg.arbitration_id, (None, None))
        if codec is None or len(msg.data) != codec.length or msg.is_extended_id != codec.message.is_extended_frame:
            self.stats.malformed += 1
            return
        values = codec.decode(msg.data)
        self.stats.commands_ok += 1
        if owner == "estop":
            self.estop = bool(values["estop.request"])
        if owner in ("estop", "pc"):
            return
        ctrl = self.controllers[owner]
        ctrl.setpoints.update(values)
        ctrl.last_cmd = self.clock()

    def _apply(self, now: float) -> None:
        sp = {name: (c.setpoints if self.state(name)[0] == sig.STATE_RUNNING else {})
              for name, c in self.controllers.items()}
        self.provider.set_drive_speed(sp["drive"].get("drive.speed_setpoint", 0.0))
        self.provider.set_clutch(sp["clutch"].get("clutch.torque_setpoint", 0.0),
                                 bool(sp["clutch"].get("clutch.open_request", 1)))
        self.provider.set_load_torque(sp["load"].get("load.torque_setpoint", 0.0))

    def _send_due(self, ctrl: _Controller, actuals: DrivetrainActuals, now: float) -> None:
        state, code = self.state(ctrl.name)
        values = {
            "drive": {"drive.speed": actuals.drive_speed_rpm, "drive.torque": actuals.drive_torque_nm},
            "clutch": {"clutch.torque": actuals.clutch_torque_nm, "clutch.position": actuals.clutch_position_mm,
                       "clutch.clamp_state": actuals.clamp_state},
            "load": {"load.torque": actuals.load_torque_nm, "load.speed": actuals.load_speed_rpm},
        }[ctrl.name]
        n = ctrl.name
        values |= {f"{n}.state": state, f"{n}.fault_code": code, f"{n}.hb_state": state}
        for alive_key in (f"{n}.alive", f"{n}.hb_alive"):
            codec = self._codec_of[alive_key]
            due = ctrl.next_due[alive_key]
            if now < due:
                continue
            cycle = codec.message.cycle_time / 1000
            ctrl.next_due[alive_key] = due + cycle if now - due < cycle else now + cycle
            if ctrl.silent:
                continue
            if not ctrl.alive_frozen:
                ctrl.alive[alive_key] = (ctrl.alive[alive_key] + 1) % self._modulo[alive_key]
            values[alive_key] = ctrl.alive[alive_key]
            self.bus.send(can.Message(arbitration_id=codec.message.frame_id, data=codec.encode(values),
                                      is_extended_id=codec.message.is_extended_frame))
            self.stats.sent += 1
