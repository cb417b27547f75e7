"""The bench as the runner sees it: the three drivers behind one small interface, hardware or simulated.

`DriverBench` opens the PT1000 scanner and the node gateway by pyserial URL and the controllers on a
python-can bus, turns their typed readings into rows of the run file's raw streams (`layout()`), each at
the time it was measured, keeps the latest values the runner's conditions and interlocks need (`status`),
integrates the friction energy frame by frame, and sends set-points. With `can_log` every CAN frame sent
and received goes to a CAN log beside the run file (BLF or ASC by suffix: python-can's writers, the BLF's
containers deflated by ISA-L). The simulated bench is only another set of URLs and another bus (plus a `service`
hook that lets the emulators run up to the shared clock's time before the drivers read).
"""

from __future__ import annotations

import functools
import logging
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from benchlab.jit import njit

from benchlab.acquire import AlignedSource, Layout, StreamSpec
from benchlab.acquire import writer as acquire_writer
from benchlab.drivetrain import DrivetrainFacts, friction_power
from benchlab.runfile.schema import ALIGNED_UNITS
from drivers import cvd
from drivers.can_signals import BENCH_DBC, BENCH_SIGNALS, CAN_ALIGNED, CAN_STREAMS, CLAMP_CLAMPED, CLAMP_SLIPPING
from drivers.clutch_node import SENSOR_STATUSES
from drivers.errors import CanLogError, ConnectionLost, DriverError
from protocols.limits import BenchLimits
from protocols.safety import OPEN_IDLE, SafeState

if TYPE_CHECKING:
    from drivers.can_bench import CanBlock

log = logging.getLogger(__name__)
STATUS_CODES = {"ok": 0.0, "open": 1.0, "short": 2.0, "range": 3.0, "fault": 4.0}
_NODE_STATUS_CODES = np.array([STATUS_CODES[s] for s in SENSOR_STATUSES])  # NodeBlock.status → stored code


@dataclass(frozen=True)
class BenchConfig:
    """Where the devices are and how their channels map; loaded from BENCH.toml or made by the sim bench."""

    instrument_url: str
    node_url: str
    can: Mapping[str, Any]
    instrument_channels: Mapping[int, str] = field(default_factory=lambda: {101: "T_air", 102: "T_housing",
                                                                             103: "T_ambient"})
    instrument_mode: str = "fres"
    instrument_baudrate: int = 115200
    instrument_timeout_s: float = 2.0
    instrument_period_s: float = 0.2
    instrument_calibration: Mapping[int, cvd.CvdCoefficients] = field(default_factory=dict)
    node_baudrate: int = 921600
    node_period_s: float = 0.05
    node_calibration: tuple[cvd.CvdCoefficients, cvd.CvdCoefficients] = (cvd.PT1000, cvd.PT1000)
    dbc: str | None = None
    can_timestamps: str = "interface"  # drivers.can_bench.TimestampSource: "run" for the simulated bus
    drivetrain: DrivetrainFacts = DrivetrainFacts()
    dt: float = 0.01
    tick_s: float = 0.1  # poll period while nothing slips
    fast_tick_s: float = 0.02  # poll period during launches, slips and right after new set-points
    flush_every_s: float = 1.0
    limits: BenchLimits = BenchLimits()
    source: str = "sim"

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "instrument": {"url": self.instrument_url, "mode": self.instrument_mode,
                "channels": {str(k): v for k, v in self.instrument_channels.items()},
                "period_s": self.instrument_period_s,
                "calibration": {str(k): c.__dict__ if hasattr(c, "__dict__") else _coef(c)
                                for k, c in self.instrument_calibration.items()}},
                "node": {"url": self.node_url, "period_s": self.node_period_s,
                         "calibration": [_coef(c) for c in self.node_calibration]},
                "can": {k: v for k, v in self.can.items()}, "dbc": self.dbc, "can_timestamps": self.can_timestamps,
                "drivetrain": dict(self.drivetrain.__dict__),
                "acquisition": {"dt": self.dt, "tick_s": self.tick_s, "fast_tick_s": self.fast_tick_s,
                                "flush_every_s": self.flush_every_s},
                "limits": self.limits.as_dict()}


def _coef(c: cvd.CvdCoefficients) -> dict[str, float]:
    return {"r0": c.r0, "a": c.a, "b": c.b, "c": c.c}


@dataclass
class BenchStatus:
    """Latest values the runner decides on (NaN/None while unknown), and the friction energy so far."""

    t: float = 0.0
    T_flywheel: float = math.nan
    T_air: float = math.nan
    engine_speed: float = math.nan
    clutch_speed: float = math.nan
    clutch_torque: float = math.nan
    clamp_state: int = 0
    friction_power: float = 0.0  # W, from the newest status frames (all of one instant)
    friction_energy_j: float = 0.0  # ∫ friction power dt over the status frames at their own times
    t_frame: float = math.nan  # run time of the newest status frame
    controllers_bad: dict[str, str] = field(default_factory=dict)
    seen: dict[str, float] = field(default_factory=dict)  # channel -> run time of its newest valid reading

    @property
    def slipping(self) -> bool:
        return self.clamp_state == CLAMP_SLIPPING

    @property
    def locked(self) -> bool:
        return self.clamp_state == CLAMP_CLAMPED

    def mark_seen(self, channel: str, t: float) -> None:
        """`channel` had a valid value measured at `t` (its age, for the stale-reading interlocks, starts again)."""
        if t > self.seen.get(channel, -math.inf):
            self.seen[channel] = t

    def take_status(self, blocks: "Sequence[CanBlock]", gear_ratio: float) -> None:
        """The status blocks of one CAN receive (at most one per controller), their frames taken in the order received:
        the energy up to each frame at the power held before it (a frame older than the newest adds none), the values
        held after each, the newest values, and when each status channel was last valid (`mark_seen`): a frame whose
        alive counter stopped, repeated or jumped is not valid (a hung controller's frozen frames go stale)."""
        held = np.array([self.engine_speed, self.clutch_speed, self.clutch_torque, float(self.clamp_state),
                         self.friction_power, self.t_frame, 0.0] + [math.nan] * len(_STATUS_HELD))
        parts = [_NO_STATUS_BLOCK] * len(_STATUS_BLOCK_ORDER)
        for b in blocks:
            alive = np.ones(len(b.t), dtype=np.bool_) if b.alive_ok is None else b.alive_ok
            parts[_STATUS_BLOCK_ORDER[b.controller]] = (b.index, b.t, b.matrix, _held_columns(b.keys), alive)
        _take_status_frames(*parts[0], *parts[1], *parts[2], held, gear_ratio)
        engine, clutch, torque, clamp, self.friction_power, self.t_frame, energy, *seen = held.tolist()
        self.engine_speed, self.clutch_speed, self.clutch_torque, self.clamp_state = engine, clutch, torque, int(clamp)
        self.friction_energy_j += energy
        for channel, t in zip(_SEEN_CHANNELS, seen):
            if t == t:  # not NaN: the channel had a valid value in this receive
                self.mark_seen(channel, t)


@njit(cache=True, nogil=True)
def actuator_slipping(clamp_state: float) -> float:  # pragma: no cover - compiled
    """1 where the clutch actuator reports slipping, 0 where clamped or open, NaN where its state is unknown."""
    return np.nan if np.isnan(clamp_state) else (1.0 if clamp_state == CLAMP_SLIPPING else 0.0)


Reading = tuple[str, "float | np.ndarray", "tuple[float, ...] | np.ndarray"]  # one row, or a block: times, rows
BenchEvent = tuple[float, str, str]  # (time, kind, detail)

_CAN_KEYS = {stream: tuple(key for _, key, _ in cols) for stream, cols in CAN_STREAMS.items()}
_STATUS_MESSAGE = {"drive": "can_drive", "clutch": "can_clutch", "load": "can_load"}


_STATUS_HELD = ("drive.speed", "load.speed", "clutch.torque", "clutch.clamp_state")  # what BenchStatus holds
_SEEN_CHANNELS = ("engine_speed", "clutch_speed", "clutch_torque")  # the stale-reading channel of each held value
_STATUS_BLOCK_ORDER = {"drive": 0, "clutch": 1, "load": 2}  # the kernel's argument group of each status message
_NO_STATUS_BLOCK = (np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, 1)), np.full(len(_STATUS_HELD), -1),
                    np.zeros(0, dtype=np.bool_))
_friction_power = njit(cache=True, nogil=True)(friction_power)  # the one formula, compiled for the kernels below


@functools.lru_cache(maxsize=32)
def _held_columns(keys: tuple[str, ...]) -> np.ndarray:
    """Per held status value (_STATUS_HELD) its column in a block with these keys, -1 where the block has none."""
    return np.array([keys.index(k) if k in keys else -1 for k in _STATUS_HELD], dtype=np.int64)


@njit(cache=True, nogil=True)
def _take_status_frames(index0: np.ndarray, t0: np.ndarray, values0: np.ndarray, columns0: np.ndarray,
                        alive0: np.ndarray, index1: np.ndarray, t1: np.ndarray, values1: np.ndarray,
                        columns1: np.ndarray, alive1: np.ndarray, index2: np.ndarray, t2: np.ndarray,
                        values2: np.ndarray, columns2: np.ndarray, alive2: np.ndarray,
                        held: np.ndarray, gear_ratio: float) -> None:  # pragma: no cover - compiled
    """Three status blocks' frames merged by arrival position and taken one by one. `held` (in/out): the four held
    values (_STATUS_HELD; clutch speed = load speed × gear ratio), friction power, newest frame time (NaN: none),
    then out: the energy added, and per held value its newest valid frame time (NaN: none; a frame whose alive
    counter was wrong, `alive*` False, is not valid)."""
    n = index0.shape[0] + index1.shape[0] + index2.shape[0]
    at = np.zeros(3, dtype=np.int64)
    for _ in range(n):
        b, best = -1, 0
        for k, index in enumerate((index0, index1, index2)):
            if at[k] < index.shape[0] and (b < 0 or index[at[k]] < best):
                b, best = k, index[at[k]]
        t, values, columns, alive = (t0, values0, columns0, alive0) if b == 0 else \
            (t1, values1, columns1, alive1) if b == 1 else (t2, values2, columns2, alive2)
        i = at[b]
        at[b] += 1
        for j in range(4):
            if columns[j] >= 0:
                value = values[i, columns[j]]
                held[j] = value * gear_ratio if j == 1 else value
                if np.isfinite(value) and alive[i] and not held[7 + j] >= t[i]:
                    held[7 + j] = t[i]
        if t[i] > held[5]:
            held[6] += held[4] * (t[i] - held[5])
            held[5] = t[i]
        elif np.isnan(held[5]):
            held[5] = t[i]
        power = _friction_power(held[2], held[0], held[1], actuator_slipping(held[3]))
        held[4] = 0.0 if np.isnan(power) else power  # unknown (NaN) counts as no power


def prime_drivers() -> None:
    """Compile (or load from numba's cache) every kernel the drivers' loop calls: the CAN bench's, the node
    gateway's, the PT1000 conversion's and the status frames' (`prime`)."""
    from drivers import can_bench, clutch_node

    for module_prime in (can_bench.prime, clutch_node.prime, cvd.prime, prime):
        module_prime()


def prime() -> None:
    """Compile (or load from numba's cache) the status kernel before a control loop calls it (a first-call compile
    there stalls the loop), on no frames and a scratch `held` (`_derived` is primed with the writer's layout)."""
    _take_status_frames(*_NO_STATUS_BLOCK * len(_STATUS_BLOCK_ORDER), np.zeros(7 + len(_STATUS_HELD)), 1.0)


def derive_aligned(out: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Grid channels computed from held ones: clutch state, friction power, mean flywheel temperature.

    Every CAN status frame sits on the grid point of the instant it was measured, so torque and slip at a grid
    point belong to the same instant.
    """
    state, power, mean = _derived(out["_clamp_state"], out["clutch_torque"], out["engine_speed"],
                                  out["clutch_speed"], out["T_flywheel_1"], out["T_flywheel_2"])
    return {"clutch_state": state, "friction_power": power, "T_flywheel": mean}


@njit(cache=True, nogil=True)
def _derived(clamp: np.ndarray, torque: np.ndarray, engine: np.ndarray, clutch: np.ndarray, f1: np.ndarray,
             f2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Per grid row: clutch state (1 slipping or clamped, 0 open, NaN unknown), friction power (the one formula),
    and the mean of the finite flywheel temperatures (NaN where neither is)."""
    n = clamp.shape[0]
    state, power, mean = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        c = clamp[k]
        state[k] = np.nan if np.isnan(c) else 1.0 if c == CLAMP_SLIPPING or c == CLAMP_CLAMPED else 0.0
        power[k] = _friction_power(torque[k], engine[k], clutch[k], actuator_slipping(c))
        total, count = 0.0, 0
        for v in (f1[k], f2[k]):
            if not np.isnan(v):
                total += v
            if np.isfinite(v):
                count += 1
        mean[k] = total / count if count else np.nan
    return state, power, mean


#: The /aligned channels the bench writes, in file order, with the contract's units (time is the grid's own;
#: T_engine is not measured: the contract's ϑ_eng = ϑ_amb).
BENCH_CHANNELS = {name: unit for name, unit in ALIGNED_UNITS.items() if name not in ("time", "T_engine")}


CAN_HOLD_CYCLES = 2.5  # a status value holds on the grid for one lost frame, not for two
REPEAT_EVENT_S = 10.0  # a device error repeating (a port gone, a muted instrument) is one event per this long


@functools.lru_cache(maxsize=8)
def load_dbc(path: str) -> Any:
    """A CAN database file parsed by cantools, once per path."""
    import cantools

    return cantools.database.load_file(path)


def duplicate_message(db: Any) -> str | None:
    """What a CAN database defines twice (a frame id or a message name held by two messages), in words; None where
    each is defined once (a decoder keyed by either would silently keep one of the two)."""
    seen: dict[object, str] = {}
    for message in db.messages:
        frame = (message.frame_id, message.is_extended_frame)
        for key, what in ((frame, f"frame id {message.frame_id:#x}"), (message.name, "message name")):
            if key in seen:
                return f"{what} of both {seen[key]} and {message.name}"
            seen[key] = message.name
    return None


def bench_dbc(config: BenchConfig) -> Any:
    """The bench's CAN database (the configured DBC or drivers/bench.dbc), parsed once per file."""
    return load_dbc(config.dbc or str(BENCH_DBC))


def status_cycle_s(config: BenchConfig, key: str) -> float:
    """DBC cycle time (s) of the status message carrying logical signal `key`."""
    message = bench_dbc(config).get_message_by_name(BENCH_SIGNALS[key][0])
    return (message.cycle_time or 100) / 1000


def bench_layout(config: BenchConfig) -> Layout:
    """Raw streams of the drivers and how /aligned is built from them (documented in docs/runfile.md)."""
    slow = max(config.tick_s, config.instrument_period_s)
    dmm_cols: list[tuple[str, str]] = []
    for name in config.instrument_channels.values():
        dmm_cols += [(name, "degC"), (f"{name}_ohm", "ohm"), (f"{name}_status", "1")]
    streams = [
        StreamSpec("instrument", tuple(dmm_cols), 1.0 / min(config.instrument_period_s, config.fast_tick_s),
                   1.5 * slow),
        StreamSpec("node", (("seq", "1"), ("node_time", "s"), ("T_flywheel_1", "degC"), ("T_flywheel_2", "degC"),
                            ("R_flywheel_1", "ohm"), ("R_flywheel_2", "ohm"), ("status_1", "1"), ("status_2", "1"),
                            ("supply", "V"), ("rssi", "dBm"), ("lqi", "1"), ("flags", "1")),
                   1.0 / config.node_period_s + 1.0, 1.5 * config.node_period_s),
    ]
    for stream, cols in CAN_STREAMS.items():
        cycle = status_cycle_s(config, cols[0][1])
        streams.append(StreamSpec(stream, tuple((c, u) for c, _, u in cols), 1.0 / cycle, CAN_HOLD_CYCLES * cycle))
    if config.can_timestamps == "interface":  # run time = CAN interface time + offset (drivers/timebase.py)
        streams.append(StreamSpec("can_clock", (("offset", "s"),), 1.0, math.inf))
    streams.append(StreamSpec("setpoints", (("engine_speed", "rpm"), ("clutch_torque", "N*m"), ("clutch_open", "1"),
                                            ("load_torque", "N*m")), 5.0, math.inf))
    sources = [AlignedSource(channel, stream, column, config.drivetrain.gear_ratio if geared else 1.0)
               for channel, stream, column, geared in CAN_ALIGNED]
    sources += [AlignedSource("T_flywheel_1", "node", "T_flywheel_1"),
               AlignedSource("T_flywheel_2", "node", "T_flywheel_2")]
    for name in config.instrument_channels.values():
        sources.append(AlignedSource(name, "instrument", name))
    units = dict(BENCH_CHANNELS)
    for name in config.instrument_channels.values():
        units.setdefault(name, "degC")
    return Layout(tuple(streams), tuple(sources), units, derive_aligned, config.dt)


BLF_OBJECT_BYTES = 48  # one classic CAN frame in a BLF container (object headers + CAN_MESSAGE)
BLF_COMPRESSION = 1  # ISA-L's level 1 (drivers.can_log.IsalBLFWriter): under half of zlib 1's CPU, the same size


def open_can_log(path: "str | os.PathLike[str]", config: BenchConfig) -> Any:
    """The CAN log writer for `path`: drivers.can_log.IsalBLFWriter for .blf (python-can's BLFWriter, containers
    deflated by ISA-L), python-can's for .asc; a BLF container holds about one second of the bus's frames.

    BLF compresses whole containers, so a killed run loses at most the container being filled: sized from the
    DBC's cycle times, that is the last second. Raises CanLogError (one line) if the file cannot be created.
    """
    import can

    from drivers.can_log import IsalBLFWriter

    suffix = Path(path).suffix.lower()
    if suffix not in (".blf", ".asc"):
        raise CanLogError(f"{path}: a CAN log ends in .blf or .asc")
    frames_per_s = sum(1000.0 / m.cycle_time for m in bench_dbc(config).messages if m.cycle_time)
    try:
        if suffix == ".asc":
            return can.Logger(str(path))
        return IsalBLFWriter(path, max_container_size=max(4096, int(frames_per_s * BLF_OBJECT_BYTES)),
                             compression_level=BLF_COMPRESSION)
    except OSError as exc:
        raise CanLogError(f"{path}: cannot be written ({exc.strerror or exc})") from None


class DriverBench:
    """The drivers of a bench (real or simulated) behind `command`/`safe_state`/`poll`."""

    def __init__(self, config: BenchConfig, clock: Callable[[], float], *, bus: Any = None,
                 service: Callable[[], None] | None = None, can_log: "str | os.PathLike[str] | None" = None,
                 companion: Any = None) -> None:
        from benchlab.runner import opening
        from drivers.can_bench import CanBench

        self.config, self.clock, self.service = config, clock, service
        self.companion = companion  # closed with the bench: the simulated devices of a partly simulated bench
        self.layout = bench_layout(config)
        # every kernel the loop calls compiled (or loaded from numba's cache) before a device is opened or commanded:
        # a first-call compile inside the loop stops polling and interlocks for seconds
        prime_drivers()
        acquire_writer.prime(self.layout)
        self.status = BenchStatus()
        self.events: list[BenchEvent] = []
        self.readings: list[Reading] = []
        channels = sorted(config.instrument_channels)
        opened: list[Callable[[], Any]] = []  # closers of the devices open so far: a later failure closes them
        try:
            self.scanner, self.idn = opening.open_scanner(
                config.instrument_url, channels, source=config.source, mode=config.instrument_mode,
                baudrate=config.instrument_baudrate, timeout=config.instrument_timeout_s,
                coefficients=dict(config.instrument_calibration), clock=clock)
            opened.append(self.scanner.close)
            self.gateway = opening.open_gateway(config.node_url, source=config.source,
                                                baudrate=config.node_baudrate, period_s=config.node_period_s,
                                                clock=clock, coefficients=config.node_calibration)
            opened.append(self.gateway.close)
            kwargs: dict[str, Any] = {"clock": clock, "idle_rpm": config.limits.idle_speed_rpm,
                                      "timestamps": config.can_timestamps}
            if config.dbc:
                kwargs["dbc"] = config.dbc
            if bus is None:
                bus = opening.open_can_bus(config.can, source=config.source)
                opened.append(bus.shutdown)
            if can_log is not None:
                kwargs["log"] = open_can_log(can_log, config)
            self.can = CanBench(bus, **kwargs)
        except BaseException:
            for closer in reversed(opened):
                try:
                    closer()
                except Exception:  # noqa: BLE001 - closing what half opened is best effort
                    pass
            raise
        self._names = [config.instrument_channels[c] for c in self.scanner.channels]
        self._next_scan = clock()
        self._setpoints: tuple[float, ...] | None = None
        self._last_error_t = -math.inf
        self._repeats: dict[str, tuple[float, int]] = {}  # kind -> (time last said, errors since)
        self._next_clock_row = -math.inf
        self._can_remaps = 0  # the CAN interface clock's re-maps already reported

    # -- commands ----------------------------------------------------------------------------------
    def command(self, engine_rpm: float, clutch_torque_nm: float, clutch_open: bool, load_nm: float) -> None:
        """Set-points to the controllers (sent at once, then cyclically by the CAN driver)."""
        self.can.set_drive_speed(engine_rpm)
        if clutch_open:
            self.can.open_clutch()
        else:
            self.can.set_clutch_torque(clutch_torque_nm)
        self.can.set_load_torque(load_nm)
        self._record_setpoints((engine_rpm, 0.0 if clutch_open else clutch_torque_nm, float(clutch_open), load_nm))

    def safe_state(self, state: SafeState = OPEN_IDLE) -> None:
        """The clutch open at zero torque, the drive and the load as `state` says (protocols/safety.py): the drive
        at idle or 0 rpm, the load at 0 or holding the torque it was last commanded (within the limits)."""
        limits = self.config.limits
        drive = limits.idle_speed_rpm if state.engine == "idle" else 0.0
        held = self._setpoints[3] if self._setpoints is not None else 0.0
        load = max(-limits.max_load_torque_nm, min(held, limits.max_load_torque_nm)) if state.load == "hold" else 0.0
        self.can.safe_state(drive, load)
        self._record_setpoints((drive, 0.0, 1.0, load))

    def _record_setpoints(self, values: tuple[float, ...]) -> None:
        if values != self._setpoints:
            self._setpoints = values
            self.readings.append(("setpoints", self.clock(), values))

    # -- polling -----------------------------------------------------------------------------------
    def poll(self) -> tuple[list[Reading], list[BenchEvent]]:
        """Everything the devices delivered since the last poll, as raw-stream rows and events.

        The cyclic CAN frames due up to now go out first, so the controllers (hardware, or the simulated bench's
        `service`) see the commands before they report.
        """
        self.can.send_due()
        if self.service is not None:
            self.service()
        now = self.clock()
        self.status.t = now
        self._poll_node(now)
        if self.scanner.scanning:  # collected first, so that the next scan due starts in the same poll: an
            self._poll_instrument(now)  # instrument whose replies take a tick (LAN, USB) still scans every period
        if not self.scanner.scanning and now >= self._next_scan - 1e-9:
            self._next_scan = max(self._next_scan + self.config.instrument_period_s, now + 1e-9)
            self._poll_instrument(now, start=True)
        self._poll_can(now)
        readings, events = self.readings, self.events
        self.readings, self.events = [], []
        for t, kind, detail in events:  # device errors, node resyncs and drop-outs, clock re-maps, controller faults
            log.info("%.3f s %s: %s", t, kind, detail)
        return readings, events

    def _poll_node(self, now: float) -> None:
        try:
            block = self.gateway.poll_block()
        except DriverError as exc:
            self._error(now, "node_error", str(exc), self.gateway.reconnect)
            return
        if len(block):  # each sample at the time the node measured it (the driver maps the node's clock)
            rows = block.table  # the node stream's columns (its own array), the status as the stored code
            rows[:, 6:8] = _NODE_STATUS_CODES[block.status]
            self.readings.append(("node", block.t, rows))
            if block.newest_measured >= 0:
                temps = [v for v in rows[block.newest_measured, 2:4].tolist() if not math.isnan(v)]
                self.status.T_flywheel = sum(temps) / len(temps)
                self.status.mark_seen("T_flywheel", block.t_measured)
        for ev in self.gateway.pop_events():
            detail = f"last seq {ev.last_seq}"
            if ev.span_s is not None:
                detail += f", span {ev.span_s:.3f} s, lost {ev.lost_frames} frames"
            if ev.offset_s is not None:
                detail += f": node clock beyond its drift allowance, mapped anew (offset {ev.offset_s:.3f} s)"
            if ev.kind == "frame_errors":  # the window's counts, so the run file adds up to the gateway's counters
                detail += f": crc_errors {ev.crc_errors}, malformed {ev.malformed}, resyncs {ev.resyncs}"
            self.events.append((ev.t_host, ev.kind, detail))

    def _poll_instrument(self, now: float, start: bool = False) -> None:
        """Start a scan (at its period) and take its readings once they are there: the loop never waits for them.

        A silent instrument is a time-out on the loop's clock (its readings go stale, the interlock trips); only
        a lost port is reconnected (a reset of a silent instrument would block the loop for its time-outs).
        """
        try:
            if start:
                self.scanner.start_scan()
            readings = self.scanner.collect()
        except ConnectionLost as exc:
            self._error(now, "instrument_error", str(exc), self.scanner.reconnect)
            return
        except DriverError as exc:
            self._error(now, "instrument_error", str(exc), None)
            return
        if readings is None:
            return
        row: list[float] = []
        t = readings[0].t_host if readings else now
        for r, name in zip(readings, self._names):
            row += [math.nan if r.temperature_c is None else r.temperature_c,
                    math.nan if r.resistance_ohm is None else r.resistance_ohm, STATUS_CODES[r.status]]
            if name == "T_air" and r.temperature_c is not None:
                self.status.T_air = r.temperature_c
                self.status.mark_seen("T_air", t)
        self.readings.append(("instrument", t, tuple(row)))
        for rec in self.scanner.error_log:
            self.events.append((rec.t_host, "instrument_error", f"{rec.code},{rec.text}"))
        self.scanner.error_log.clear()

    def _poll_can(self, now: float) -> None:
        try:
            blocks = self.can.receive_blocks()
        except CanLogError:
            raise
        except Exception as exc:  # noqa: BLE001 - a bus error is an event, the watchdog does the rest
            self._error(now, "can_error", str(exc), None)
            return
        st = self.status
        status = [b for b in blocks if b.controller in _STATUS_MESSAGE and b.message.endswith("_Status")]
        for b in status:  # one block of rows per stream, each frame at its own time
            stream = _STATUS_MESSAGE[b.controller]
            self.readings.append((stream, b.t, b.columns(_CAN_KEYS[stream])))
        if status:
            st.take_status(status, self.config.drivetrain.gear_ratio)
        for ev in self.can.pop_events():
            if ev.kind == "alive_error":  # a hung controller repeats one every frame: summarised (its values go stale)
                self._event(ev.t, "controller_alive_error", f"{ev.controller}: {ev.detail}")
            else:
                self.events.append((ev.t, f"controller_{ev.kind}", f"{ev.controller}: {ev.detail}"))
        st.controllers_bad = {**{c: "silent" for c in self.can.silent}, **{c: "fault" for c in self.can.faulted}}
        if self.can.clock_map.remaps > self._can_remaps:  # the interface's clock drifted beyond its allowance or jumped
            self.events.append((now, "can_clock_remapped", f"CAN interface clock mapped anew (offset "
                                                           f"{self.can.clock_map.offset:.3f} s)"))
            self._can_remaps = self.can.clock_map.remaps
        if self.can.timestamps == "interface" and math.isfinite(self.can.clock_map.offset) and now >= self._next_clock_row:
            self.readings.append(("can_clock", now, (self.can.clock_map.offset,)))
            log.debug("%.3f s CAN interface clock: run time = interface time %+.6f s", now, self.can.clock_map.offset)
            self._next_clock_row = now + 1.0

    def _error(self, now: float, kind: str, detail: str, reconnect: Callable[[], None] | None) -> None:
        """A device error: an event (the same one repeating is summarised), and a reconnect at most once a second."""
        self._event(now, kind, detail)
        if reconnect is not None and now - self._last_error_t > 1.0:
            self._last_error_t = now
            try:
                reconnect()
            except DriverError as exc:
                self._event(now, kind, f"reconnect failed: {exc}")

    def _event(self, now: float, kind: str, detail: str) -> None:
        """An event, at most one per kind every REPEAT_EVENT_S: the errors in between are counted in the next one."""
        last = self._repeats.get(kind)
        if last is not None and now - last[0] < REPEAT_EVENT_S:
            self._repeats[kind] = (last[0], last[1] + 1)
            return
        repeated = f" (and {last[1]} more {kind} in {now - last[0]:.0f} s)" if last is not None and last[1] else ""
        self.events.append((now, kind, detail + repeated))
        self._repeats[kind] = (now, 0)

    def close(self) -> None:
        closers = [self.scanner.close, self.gateway.close, self.can.close]
        if self.companion is not None:
            closers.append(self.companion.close)
        for closer in closers:
            try:
                closer()
            except Exception:  # noqa: BLE001 - closing is best effort
                pass
