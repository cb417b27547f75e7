"""Bench controllers on CAN (drive motor, clutch actuator, load machine): set-points out, actual values in.

The driver works on logical signal names (drivers/can_signals.py) so a vendor DBC plus a mapping replaces
ours. Every received frame keeps the time it was measured: the interface's time stamp (`msg.timestamp`)
mapped onto the run clock (`timestamps="interface"`, drivers/timebase.py), taken as it is where the bus
already stamps on the run clock (`"run"`, the simulated bench), or the receive time where the interface
gives none (`"receive"`). `poll()` = `send_due()` (every cyclic command frame, PC heartbeat and, while
active, emergency stop that fell due since the last call, at its DBC cycle) + `receive()` (every waiting
frame, none dropped, decoded and watched: silent = a watched message not seen within `silent_cycles` cycle
times; faulted = fault code ≠ 0 or fault state; alive counter not +1). Frames with an unknown id or a wrong
DLC are counted, never decoded. With a `log` (a python-can Listener such as `can.Logger("run.blf")`) every
frame sent and received is logged, sorted by time at each `receive()`, in the bus's time base; a log that cannot be written
raises CanLogError.
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

from drivers import can_signals as sig
from drivers.can_codec import MessageCodec, compile_codecs
from drivers.errors import CanBusError, CanConfigError, CanLogError
from drivers.timebase import ClockMap

EventKind = Literal["silent", "back", "fault", "fault_cleared", "alive_error", "estop", "estop_released"]
TimestampSource = Literal["interface", "run", "receive"]
LOG_SYNC_S = 1.0  # the log file is flushed to the OS this often
MAX_CATCH_UP_S = 1.0  # a cyclic frame more than this late is skipped, not sent in a burst


@dataclass(frozen=True, slots=True)
class CanSample:
    """One decoded frame: run-clock time it was received by the interface, logical signal → physical value."""

    t: float
    controller: str
    message: str
    values: dict[str, float]


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


@dataclass(slots=True)
class _Rx:
    """How to decode and watch one received message."""

    codec: MessageCodec
    controller: str
    timeout_s: float | None
    alive_key: str | None
    alive_modulo: int
    fault_key: str | None
    state_key: str | None
    last_seen: float
    last_alive: int | None = None


@dataclass(slots=True)
class _Tx:
    """A message the PC sends: its current values (logical keys), alive key and cyclic schedule."""

    codec: MessageCodec
    values: dict[str, float]
    alive_key: str | None
    alive_modulo: int
    cycle_s: float
    origin: float
    cycles: int = 0  # cyclic frames due so far: the next falls due at origin + cycles * cycle_s

    @property
    def next_due(self) -> float:
        return self.origin + self.cycles * self.cycle_s


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
        self.latest: dict[str, float] = {}
        self.estop_active = False
        self._events: list[ControllerEvent] = []
        self._silent: dict[str, str] = {}
        self._faulted: dict[str, bool] = {}
        self._to_log: list[can.Message] = []
        self._log_synced = -math.inf
        now = clock()
        self._rx, self._tx = self._compile(signals, silent_cycles, now)
        self._tx_of = {key: tx for tx in self._tx.values() for key in tx.codec.names.values()}

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

    def safe_state(self) -> None:
        """Clutch open with zero torque, load torque 0, drive at idle speed; sent at once."""
        self._set({"clutch.torque_setpoint": 0.0, "clutch.open_request": 1, "load.torque_setpoint": 0.0,
                   "drive.speed_setpoint": self.idle_rpm})

    def emergency_stop(self, source: int = sig.ESTOP_SOURCE_PC) -> None:
        """Send the emergency stop now and repeat it every cycle until `release_emergency_stop()`."""
        self.estop_active = True
        tx = self._tx_of["estop.request"]
        tx.origin, tx.cycles = self.clock() + tx.cycle_s, 0
        self._set({"estop.request": 1, "estop.source": source})

    def release_emergency_stop(self) -> None:
        """Send one emergency-stop release and stop repeating it."""
        self._set({"estop.request": 0})
        self.estop_active = False

    # -- the bus -----------------------------------------------------------------------------------
    def poll(self) -> list[CanSample]:
        """`send_due()`, then `receive()`."""
        self.send_due()
        return self.receive()

    def send_due(self) -> None:
        """Send every cyclic frame that fell due up to now, each stamped with its due time (not listen-only)."""
        if self.listen_only:
            return
        now = self.clock()
        for tx in self._tx.values():
            if not tx.cycle_s or (tx is self._tx_of.get("estop.request") and not self.estop_active):
                continue
            if now - tx.next_due > MAX_CATCH_UP_S:
                skipped = int((now - tx.next_due) // tx.cycle_s)
                tx.cycles += skipped
                self.stats.late_skipped += skipped
            while tx.next_due <= now + 1e-9:
                self._send(tx, min(tx.next_due, now))
                tx.cycles += 1

    def receive(self) -> list[CanSample]:
        """Every waiting frame at its own time, decoded and watched; then the silence watchdog at now."""
        now = self.clock()
        try:
            frames = list(iter(lambda: self.bus.recv(timeout=0), None))
        except can.CanError as exc:  # the interface itself failed (bus-off, adapter gone)
            raise CanBusError(f"receiving: {exc}") from exc
        if self.log is not None:
            self._to_log += frames
        if self.timestamps == "interface":  # the whole batch first: its fastest frame shows the offset best
            for msg in frames:
                if msg.timestamp:
                    self.clock_map.observe(msg.timestamp, now)
        samples = []
        for msg in frames:
            if not msg.is_rx:  # our own frame echoed by the interface: logged, not decoded
                continue
            sample = self.handle(msg, self._frame_time(msg, now))
            if sample is not None:
                samples.append(sample)
        self._watch(now)
        self._flush_log()
        return samples

    def handle(self, msg: can.Message, t: float) -> CanSample | None:
        """Decode and watch one received frame measured at run time `t`; None (and a counter) if not decodable."""
        stats = self.stats
        if msg.is_error_frame or msg.is_remote_frame:
            stats.error_frames += 1
            return None
        rx = self._rx.get((msg.arbitration_id, msg.is_extended_id))
        if rx is None:
            stats.unknown_id += 1
            return None
        if len(msg.data) != rx.codec.length:
            stats.bad_dlc += 1
            return None
        try:
            values = rx.codec.decode(msg.data)
        except ValueError:
            stats.decode_errors += 1
            return None
        stats.frames_ok += 1
        rx.last_seen = max(rx.last_seen, t)
        self.latest.update(values)
        if rx.alive_key is not None:
            self._check_alive(rx, int(values[rx.alive_key]), t)
        if rx.controller == "estop":
            self._event(t, "estop", "estop" if values.get("estop.request") else "estop_released",
                        f"source {values.get('estop.source')}")
        elif rx.fault_key or rx.state_key:
            self._check_fault(rx, values, t)
        return CanSample(t, rx.controller, rx.codec.message.name, values)

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
    def _frame_time(self, msg: can.Message, now: float) -> float:
        if self.timestamps == "run":
            return msg.timestamp
        if self.timestamps == "interface" and msg.timestamp:
            return min(self.clock_map.to_run(msg.timestamp), now)
        return now

    def _bus_time(self, t: float) -> float:
        """A run time in the bus's time base (for the frames the PC sends, as logged)."""
        return self.clock_map.to_device(t) if self.timestamps == "interface" else t

    def _compile(self, signals: Mapping[str, tuple[str, str]], silent_cycles: float,
                 now: float) -> tuple[dict[tuple[int, bool], _Rx], dict[str, _Tx]]:
        rx: dict[tuple[int, bool], _Rx] = {}
        tx: dict[str, _Tx] = {}
        for name, codec in compile_codecs(self.db, signals).items():
            message, keys = codec.message, {key: signal for signal, key in codec.names.items()}
            alive = next((k for k in keys if k.endswith("alive")), None)
            modulo = 1 << message.get_signal_by_name(keys[alive]).length if alive else 0
            cycle_s = (message.cycle_time or 0) / 1000
            controller = next(iter(keys)).split(".")[0]
            sent_by_pc = all(k in sig.TX_KEYS for k in keys)
            if sent_by_pc:
                tx[name] = _Tx(codec, dict.fromkeys(keys, 0.0), alive, modulo, cycle_s, now)
            if controller == "estop" or not sent_by_pc:
                timeout = cycle_s * silent_cycles if cycle_s and controller != "estop" else None
                fault, state = f"{controller}.fault_code", f"{controller}.state"
                rx[(message.frame_id, message.is_extended_frame)] = _Rx(
                    codec, controller, timeout, alive, modulo, fault if fault in keys else None,
                    state if state in keys else None, now)
        return rx, tx

    def _set(self, updates: Mapping[str, float]) -> None:
        if self.listen_only:
            raise CanConfigError("CanBench was opened listen-only; it sends nothing")
        touched = {}
        for key, value in updates.items():
            tx = self._tx_of[key]
            tx.values[key] = value
            touched[id(tx)] = tx
        now = self.clock()
        for tx in touched.values():
            self._send(tx, now)

    def _send(self, tx: _Tx, t: float) -> None:
        if tx.alive_key is not None:
            tx.values[tx.alive_key] = (int(tx.values[tx.alive_key]) + 1) % tx.alive_modulo
        message = tx.codec.message
        msg = can.Message(timestamp=self._bus_time(t), arbitration_id=message.frame_id,
                          data=tx.codec.encode(tx.values), is_extended_id=message.is_extended_frame, is_rx=False)
        try:
            self.bus.send(msg)
            self.stats.sent += 1
        except can.CanError:
            self.stats.send_errors += 1
            return
        if self.log is not None:
            self._to_log.append(msg)

    def _flush_log(self) -> None:
        if not self._to_log or self.log is None:
            return
        frames, self._to_log = sorted(self._to_log, key=_timestamp), []
        try:
            for msg in frames:
                self.log.on_message_received(msg)
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

    def _check_alive(self, rx: _Rx, alive: int, t: float) -> None:
        if rx.last_alive is not None and alive != (rx.last_alive + 1) % rx.alive_modulo:
            self.stats.alive_errors += 1
            self._event(t, rx.controller, "alive_error", f"{rx.codec.message.name}: {rx.last_alive} → {alive}")
        rx.last_alive = alive

    def _check_fault(self, rx: _Rx, values: Mapping[str, float], t: float) -> None:
        code = int(values.get(rx.fault_key, 0))
        state = values.get(rx.state_key)
        faulted = code != 0 or state == self.fault_state
        if faulted != self._faulted.get(rx.controller, False):
            self._faulted[rx.controller] = faulted
            self._event(t, rx.controller, "fault" if faulted else "fault_cleared", f"state {state}, code {code}")

    def _watch(self, now: float) -> None:
        overdue: dict[str, str] = {}
        for rx in self._rx.values():
            if rx.timeout_s is not None and now - rx.last_seen > rx.timeout_s:
                overdue.setdefault(rx.controller, rx.codec.message.name)
        for controller in {rx.controller for rx in self._rx.values()}:
            was, now_silent = controller in self._silent, controller in overdue
            if now_silent and not was:
                self._silent[controller] = overdue[controller]
                self._event(now, controller, "silent", f"no {overdue[controller]} for > {self._timeout_of(overdue[controller])} s")
            elif was and not now_silent:
                del self._silent[controller]
                self._event(now, controller, "back")

    def _timeout_of(self, message: str) -> float | None:
        return next(rx.timeout_s for rx in self._rx.values() if rx.codec.message.name == message)

    def _event(self, t: float, controller: str, kind: EventKind, detail: str = "") -> None:
        self._events.append(ControllerEvent(t, controller, kind, detail))

    @property
    def silent(self) -> dict[str, str]:
        """Controllers currently silent → the overdue message."""
        return dict(self._silent)

    @property
    def faulted(self) -> set[str]:
        """Controllers currently reporting a fault."""
        return {c for c, f in self._faulted.items() if f}


def _timestamp(msg: can.Message) -> float:
    return msg.timestamp
