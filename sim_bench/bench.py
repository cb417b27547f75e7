"""The simulated bench: drivetrain + thermal plant + sensors wired into the device emulators as their providers.

The runner talks to the *drivers* exactly as on hardware: the scanning DMM and the flywheel node's PC
gateway behind `sim://` serial URLs, the three controllers on an in-process CAN bus. This module only
supplies what the devices measure and when:

* `SimPhysics` implements the emulators' provider interfaces (DrivetrainProvider, ResistanceProvider,
  NodeInputProvider). It advances the analytic drivetrain and the thermal plant (batch ZOH solver) in
  chunks of `chunk_s` on a `dt` grid, assuming the set-points hold; when a set-point changes inside a
  computed chunk, the chunk is cut at that instant and recomputed from the stored state there. So the
  physics costs one solver call per chunk or set-point change, not one per device reading.
* Sensor noise and quantisation of every reading, ambient drift, radio drop-outs (the node emulator's
  `radio_silence`), all from one seeded generator per purpose: the same seed gives the same run.
* Fault hooks used by `sim_bench.faults` (heaters, a stuck clutch, ...).

`SimulatedBench` is the simulated bench a run asks for (`RunRequest.bench`): plant, faults, configuration
overrides and limits in one object that opens its `SimBench` for the runner's `open_bench`.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from benchlab.jit import njit

from drivers import cvd
from drivers.can_signals import CLAMP_CLAMPED, CLAMP_OPEN, CLAMP_SLIPPING
from protocols.limits import BenchLimits
from sim_bench.clock import SimClock
from benchlab.drivetrain import DrivetrainFacts
from sim_bench.drivetrain import Drivetrain
from sim_bench.truth_store import TruthStore
from sim_bench.emulators import can_controllers, clutch_node, registry, sim_can_bus
from sim_bench.emulators.can_controllers import CanBenchEmulator
from sim_bench.emulators.clutch_node import ClutchNodeEmulator
from sim_bench.emulators.drivetrain import DrivetrainActuals
from sim_bench.emulators.providers import NodeInputs, NodeInputSeries
from sim_bench.emulators.scpi_instrument import ScpiInstrumentEmulator
from sim_bench.emulators.sim_can_bus import SimCanBus
from sim_bench.plant import Effect, ThermalPlant, custom_source
from sim_bench.reference_plant import reference_plant
from sim_bench.virtual_run import AmbientConfig, SensorConfig

if TYPE_CHECKING:
    from benchlab.runner.devices import BenchConfig
    from sim_bench.faults import Fault


_ids = itertools.count()
DMM_CHANNELS = {101: "T_air", 102: "T_housing", 103: "T_ambient"}
MAX_DROPOUT_MEANS = 4.0  # radio drop-outs are exponential, cut at 4 means (8 s): longer silence is a fault
MU_PERIOD_S = 2.0  # the lining's μ(ϑ) is held over periods this long (a launch lasts 1-6 s; 1 s cost 12 % of the bench's speed)


@dataclass(frozen=True)
class SimBenchConfig:
    """Everything the simulated bench needs besides the plant: seed, grids, sensors, drop-outs."""

    seed: int = 1
    dt: float = 0.01
    chunk_s: float = 10.0
    sensors: SensorConfig = SensorConfig()
    ambient: AmbientConfig = AmbientConfig()
    drivetrain: DrivetrainFacts = DrivetrainFacts()
    node_period_s: float = 0.05
    dmm_channels: Mapping[int, str] = field(default_factory=lambda: dict(DMM_CHANNELS))
    initial_c: float | Mapping[str, float] | None = None  # None: everything at ambient
    t0: float = 0.0
    dropouts: bool = True
    position_stroke_mm: float = 8.0

    def as_dict(self) -> dict[str, Any]:
        return {"seed": self.seed, "dt": self.dt, "chunk_s": self.chunk_s, "sensors": self.sensors.__dict__,
                "ambient": self.ambient.__dict__, "drivetrain": dict(self.drivetrain.__dict__), "node_period_s": self.node_period_s,
                "dmm_channels": {str(k): v for k, v in self.dmm_channels.items()}, "dropouts": self.dropouts}


def fault_heater_effects() -> tuple[Effect, ...]:
    """Zero heat sources on flywheel and air, driven by the channels `fault_heat_F`/`fault_heat_A` (W)."""
    return (custom_source("fault heater F", "F", "fault", "heat_source", lambda ch: ch["fault_heat_F"]),
            custom_source("fault heater A", "A", "fault", "heat_source", lambda ch: ch["fault_heat_A"]))


class SimPhysics:
    """Provider of the CAN, DMM and node emulators: chunked drivetrain + thermal plant + sensor noise."""

    def __init__(self, config: SimBenchConfig, clock: SimClock, plant: ThermalPlant | None = None) -> None:
        self.cfg, self.clock, self.dt = config, clock, config.dt
        base = plant or reference_plant()
        # the bench's own plant, plus fault heaters (zero unless a fault is injected)
        self.plant = base.with_effects(fault_heater_effects())
        self.truth_params = dict(base.params)
        self.plant_name = base.name
        seed = config.seed
        self.rng_sensor = np.random.default_rng([seed, 1])
        self.rng_dropout = np.random.default_rng([seed, 2])
        self.drivetrain = Drivetrain(config.drivetrain)
        self.gear = config.drivetrain.gear_ratio
        k0 = self._index(config.t0)
        amb0 = self._ambient(np.array([k0]))[0]
        init = config.initial_c
        if isinstance(init, Mapping):  # states not given (extra nodes, sensor lags) start like the flywheel
            init = {name: float(init.get(name, init.get("F", amb0))) for name in self.plant.state_names}
        self.plant.reset(amb0 if init is None else init)
        self._chunks: list[tuple[int, dict[str, np.ndarray], dict[str, np.ndarray]]] = []
        self._end = k0  # first index not computed yet
        # μ(ϑ) of the lining, held over fixed periods of the grid (MU_PERIOD_S, from the state at each period's start),
        # so that how the run is cut into chunks never changes the torque: period index -> factor
        self._mu_period = max(1, int(round(MU_PERIOD_S / self.dt)))
        self._mu: dict[int, float] = {}
        self.fault_heat = {"F": 0.0, "A": 0.0}
        self.stuck: tuple[float, float] | None = None  # (clutch torque, until t): clutch clamped, output braked
        self._setpoints = (0.0, False, 0.0, 0.0)
        self.t_setpoints = config.t0  # set-points given now hold from this time (the controllers' last advance)
        self.computed_s = 0.0
        self.solver_calls = 0
        self._truth_k0 = k0  # grid index of the first recorded true state
        self._truth: TruthStore | None = None  # the bench's own recording, made when first needed (`_keep_truth`)
        #: where the true states of grid points k0 … go once final (first grid index, (n, states) array): the
        #: bench's own recording, or a run file's /truth (`SimBench.record_truth_into`)
        self.truth_sink: Callable[[int, np.ndarray], None] = self._keep_truth
        self.prime()

    def prime(self) -> None:
        """Compile (or load from numba's cache) the physics' kernels now rather than at the first answer that needs
        them: on wall-clock time a compile there (seconds on a cold cache) silences the emulated controllers past
        the driver's limit. The look-ups on no times, drivetrain and plant on two samples from a copy of the
        drivetrain, nothing computed kept (state, chunks, random generators unchanged)."""
        width = len(_ACTUAL_SOURCES) + 3  # + speed noise (2) and torque noise, as `_compute` stacks them
        _grid_rows(np.zeros(0), self.dt, self._end, np.zeros((0, 2)))
        _measured_at(np.zeros(0), self.dt, self._end, np.zeros((0, width)), self.cfg.position_stroke_mm, self.gear)
        _measured(np.zeros((0, width)), self.cfg.position_stroke_mm, self.gear)
        self.plant.prime(self._channels(copy.copy(self.drivetrain), self._end, 2), self.dt)

    # -- grid and chunks -----------------------------------------------------------------------------
    def _index(self, t: float) -> int:
        return grid_index(t, self.dt)

    def _ambient(self, k: np.ndarray) -> np.ndarray:
        a = self.cfg.ambient
        return a.mean_c + a.drift_k * np.sin(2 * np.pi * k * self.dt / a.period_s)

    def _compute(self, n: int) -> None:
        k0 = self._end
        self._apply_stuck(k0 * self.dt)
        cols, states = self._advance(k0, n)
        temps = self.plant.sensor_temperatures(states, (k0 + np.arange(n)) * self.dt)
        temps["_states"] = np.column_stack([states[s] for s in self.plant.state_names])
        # what the sensors read on this grid: the node's two sensors, then the DMM's channels, one row each: noise
        # per sample (drawn row after row, one call per noise level), resistances in one vectorised call
        sc, rng = self.cfg.sensors, self.rng_sensor
        noisy = np.stack([temps["T_flywheel_1"], temps["T_flywheel_2"]] + [cols["T_ambient"] if name == "T_ambient" else temps[name]
                                                      for name in self.cfg.dmm_channels.values()])
        noisy[:2] += rng.normal(0.0, sc.node_noise_k, (2, n))
        noisy[2:] += rng.normal(0.0, sc.wired_noise_k, (len(noisy) - 2, n))
        resistances = cvd.resistance(noisy)
        temps["_R_node"] = np.ascontiguousarray(resistances[:2].T)
        for i, ch in enumerate(self.cfg.dmm_channels, start=2):
            temps[f"_R_dmm{ch}"] = resistances[i]
        noise_speed = rng.normal(0.0, sc.speed_noise_rpm, (n, 2))
        noise_torque = rng.normal(0.0, sc.torque_noise_nm, n)
        # what the controllers' actual values are made of, one row per grid point (actuals_at takes rows)
        temps["_actuals"] = np.column_stack([cols[c] for c in _ACTUAL_SOURCES] + [noise_speed, noise_torque])
        self._chunks.append((k0, cols, temps))
        if len(self._chunks) > 3:  # older than any cut can reach (`_cut`): its true states are final
            first, _, final = self._chunks.pop(0)
            self.truth_sink(first, final["_states"])
        self._end = k0 + n
        self.computed_s += n * self.dt
        self.solver_calls += 1

    def _ensure(self, k: int) -> None:
        while k >= self._end:
            n = max(int(round(self.cfg.chunk_s / self.dt)), k - self._end + 1)
            self._compute(n)

    def _at(self, t: float) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], int]:
        k = self._index(t)
        self._ensure(k)
        for k0, cols, temps in reversed(self._chunks):
            if k >= k0:
                return cols, temps, k - k0
        k0, cols, temps = self._chunks[0]  # older than kept: the oldest sample we have
        return cols, temps, 0

    def _channels(self, drivetrain: Drivetrain, k0: int, n: int) -> dict[str, np.ndarray]:
        """The plant's channels on grid points k0 .. k0+n-1: `drivetrain` advanced over them, ambient, fault heat."""
        drivetrain.torque_factor = self._friction_factor(k0)
        cols = drivetrain.advance(n, self.dt)
        if self.stuck is not None:
            cols["clutch_state"][:] = 1.0
        cols["T_ambient"] = self._ambient(np.arange(k0, k0 + n))
        cols["fault_heat_F"] = np.full(n, self.fault_heat["F"])
        cols["fault_heat_A"] = np.full(n, self.fault_heat["A"])
        return cols

    def _advance(self, k0: int, n: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The channels and true states on grid points k0 .. k0+n-1, the plant advanced over them: in one piece, or
        for a plant with μ(ϑ) piece by piece along μ's periods (each piece's torque from its period's factor)."""
        pieces, k = [], k0
        while k < k0 + n:
            end = self._piece_end(k, k0 + n)
            cols = self._channels(self.drivetrain, k, end - k)
            pieces.append((cols, self.plant.advance(cols, self.dt)))
            self._note_periods(k, end, pieces[-1][1])
            k = end
        if len(pieces) == 1:
            return pieces[0]
        return ({name: np.concatenate([c[name] for c, _ in pieces]) for name in pieces[0][0]},
                {name: np.concatenate([t[name] for _, t in pieces]) for name in pieces[0][1]})

    def _piece_end(self, k: int, stop: int) -> int:
        """Where the plant's piece from grid point k ends: at the next μ period while the clutch slips (the torque it
        transmits reads μ), else at `stop`. Set-points hold over a chunk, so a clutch that does not slip at k (open,
        or clamped and locked) does not slip again before the chunk ends, and μ changes nothing there: one piece
        instead of one per period (the plant's laws iterated once over it, not once per 2 s)."""
        if self.plant.friction is None or not self.drivetrain.slipping:
            return stop
        return min(stop, (k // self._mu_period + 1) * self._mu_period)

    def _note_periods(self, k: int, end: int, states: Mapping[str, np.ndarray]) -> None:
        """μ of every period that starts inside the piece k..end, from the plant's state at its start, as a piece per
        period would have taken it: a cut inside such a period starts its launch from that μ."""
        if self.plant.friction is None:
            return
        first = k // self._mu_period + 1
        for period in range(first, (end - 1) // self._mu_period + 1):
            row = period * self._mu_period - k
            self._mu[period] = self.plant.friction_factor(np.array([states[s][row] for s in self.plant.state_names]))

    def _friction_factor(self, k0: int) -> float:
        """μ(ϑ)/μ_cal for the period holding grid point k0: from the plant's state at the period's start (taken when
        a chunk starts there, kept for a chunk that starts inside it after a cut)."""
        period = k0 // self._mu_period
        if k0 % self._mu_period == 0 or period not in self._mu:
            self._mu[period] = self.plant.friction_factor()
            oldest = (self._chunks[0][0] if self._chunks else self._end) // self._mu_period  # a cut reaches that far
            for old in [p for p in self._mu if p < oldest]:
                del self._mu[old]
        return self._mu[period]

    def _cut(self, t: float) -> None:
        """Set-points change at t: drop everything computed from the first grid point at or after t, restore the state there."""
        k = int(math.ceil(t / self.dt - 1e-6))
        if k > self._end:
            self._ensure(k - 1)
        if k >= self._end or not self._chunks:  # nothing kept before _end: the plant's state is _end's, it holds from there
            return
        k = max(k, self._chunks[0][0])  # a command stamped before the oldest state still kept takes effect from there
        while self._chunks and self._chunks[-1][0] > k:
            self._chunks.pop()
        k0, cols, temps = self._chunks[-1]
        i = k - k0
        self.drivetrain.clutch_rpm = float(cols["clutch_speed"][i])
        self.plant.state = temps["_states"][i].copy()
        self._chunks[-1] = (k0, {n: c[:i] for n, c in cols.items()}, {n: v[:i] for n, v in temps.items()})
        if i == 0:
            self._chunks.pop()
        self._end = k

    def _change(self, engine: float, clamped: bool, torque: float, load: float) -> None:
        new = (float(engine), bool(clamped), float(torque), float(load))
        if new == self._setpoints:
            return
        t = self.t_setpoints
        self._cut(t)
        self._setpoints = new
        self._apply_stuck(t)

    def _apply_stuck(self, t: float) -> None:
        engine, clamped, torque, load = self._setpoints
        if self.stuck is not None and t < self.stuck[1]:
            self.drivetrain.set_points(engine, True, self.stuck[0], 2.0 * self.gear * self.stuck[0])
            self.drivetrain.clutch_rpm = 0.0
        else:
            self.stuck = None
            self.drivetrain.set_points(engine, clamped, torque if clamped else 0.0, load)

    # -- fault hooks -----------------------------------------------------------------------------------
    def set_fault_heat(self, node: str, watts: float) -> None:
        """A heater on the flywheel ("F") or the chamber air ("A") from now on (0 switches it off)."""
        t = self.clock()
        self._cut(t)
        self.fault_heat[node] = float(watts)

    def stick_clutch(self, torque_nm: float, duration_s: float) -> None:
        """Clutch clamped at `torque_nm` and the output braked for `duration_s`, whatever is commanded."""
        t = self.clock()
        self._cut(t)
        until = t + duration_s if self.stuck is None else max(self.stuck[1], t + duration_s)  # extends, never shortens
        self.stuck = (float(torque_nm), until)
        self._apply_stuck(t)

    # -- DrivetrainProvider (CAN controllers) ------------------------------------------------------------
    def set_drive_speed(self, rpm: float) -> None:
        _, clamped, torque, load = self._setpoints
        self._change(rpm, clamped, torque, load)

    def set_clutch(self, torque_nm: float, open_request: bool) -> None:
        engine, _, _, load = self._setpoints
        self._change(engine, not open_request, 0.0 if open_request else max(0.0, torque_nm), load)

    def set_load_torque(self, torque_nm: float) -> None:
        engine, clamped, torque, _ = self._setpoints
        self._change(engine, clamped, torque, torque_nm)

    def advance(self, t: float) -> None:
        if self.stuck is not None and t >= self.stuck[1]:
            until = self.stuck[1]
            self._cut(until)
            self.stuck = None
            self._apply_stuck(until)
        self._ensure(self._index(t))
        self.t_setpoints = t

    def _newest_chunk(self, times: np.ndarray) -> tuple[int, dict[str, np.ndarray]] | None:
        """Compute up to the last of `times` (increasing); the newest chunk's (first grid index, matrices) if all of
        `times` fall in it, else None."""
        self._ensure(self._index(times[-1]))
        k0, _, temps = self._chunks[-1]
        return (k0, temps) if self._index(times[0]) >= k0 else None

    def _rows_at(self, times: "np.ndarray | list[float]", name: str) -> np.ndarray:
        """Rows of the per-grid-point matrix `name` at each of `times` (increasing), computed where needed."""
        times = np.asarray(times, dtype=float)
        newest = self._newest_chunk(times)
        if newest is not None:  # the usual case
            return _grid_rows(times, self.dt, newest[0], newest[1][name])
        k = np.array([self._index(t) for t in times.tolist()], dtype=np.int64)  # not all in the newest chunk: rare
        k = np.maximum(k, self._chunks[0][0])  # older than kept: the oldest sample we have
        rows = np.empty((len(k), self._chunks[-1][2][name].shape[1]))
        for k0, _, temps in self._chunks:
            sel = (k >= k0) & (k < k0 + len(temps[name]))
            rows[sel] = temps[name][k[sel] - k0]
        return rows

    def actuals_matrix(self, times: np.ndarray) -> np.ndarray:
        """What the controllers measure at each of `times` (DrivetrainActuals' fields by row, one column per time):
        the drivetrain's values plus sensor noise; the usual case (all in the newest chunk) in one compiled pass."""
        times = np.asarray(times, dtype=float)
        newest = self._newest_chunk(times)
        if newest is not None:
            return _measured_at(times, self.dt, newest[0], newest[1]["_actuals"], self.cfg.position_stroke_mm,
                                self.gear)
        return _measured(self._rows_at(times, "_actuals"), self.cfg.position_stroke_mm, self.gear)

    def actuals_at(self, times: np.ndarray) -> DrivetrainActuals:
        """`actuals_matrix` as DrivetrainActuals."""
        return DrivetrainActuals(*self.actuals_matrix(times))

    # -- ResistanceProvider (DMM) -----------------------------------------------------------------------
    def get_resistances(self) -> Mapping[int, float]:
        _, temps, i = self._at(self.clock())
        return {ch: float(temps[f"_R_dmm{ch}"][i]) for ch in self.cfg.dmm_channels}

    # -- NodeInputProvider (flywheel node) -----------------------------------------------------------
    def node_inputs(self, t: float) -> NodeInputs:
        """What the flywheel node measures at `t`."""
        r1, r2 = self.node_inputs_at(np.array([t])).resistances_ohm[0].tolist()
        return NodeInputs((r1, r2))

    def node_inputs_at(self, times: np.ndarray) -> NodeInputSeries:
        """What the node measures at each of `times` (increasing), in one look-up: the emulator asks once per read."""
        return NodeInputSeries(self._rows_at(times, "_R_node"))

    # -- truth, for tests and analysis ----------------------------------------------------------------
    def _keep_truth(self, k0: int, states: np.ndarray) -> None:
        """Keep final true states of grid points k0 onwards in the bench's own recording, on disk
        (sim_bench.truth_store): the sink when no run file takes them (tests, analysis)."""
        if self._truth is None:
            self._truth = TruthStore(len(self.plant.state_names))
        self._truth.write(k0 - self._truth_k0, states)

    def hand_over_truth(self) -> None:
        """The run ends: the true states still kept (the last chunks, not final while a set-point could change)
        to `truth_sink` too, up to the last grid point computed."""
        for k0, _, temps in self._chunks:
            self.truth_sink(k0, temps["_states"])

    def truth_channels(self) -> list[str]:
        """The names of the true states, in the order of their columns (the plant's `state_names`), by
        `state_channels` of the plant's network."""
        from benchlab.network import state_channels

        names = state_channels(self.plant.network)
        return [names[s] for s in self.plant.state_names]

    def true_states(self, rows: int) -> dict[str, np.ndarray]:
        """The plant's true temperatures (degC) on grid rows [first recorded, `rows`) as the bench's own recording
        holds them (no run file attached): the final rows, then the chunks still kept; NaN where not computed."""
        n = max(rows - self._truth_k0, 0)
        states = np.full((n, len(self.plant.state_names)), np.nan)
        if self._truth is not None:
            for i in range(states.shape[1]):
                states[:, i] = self._truth.read(i, 0, n)
        for k0, _, temps in self._chunks:
            rows_kept = temps["_states"][:max(n - (k0 - self._truth_k0), 0)]
            states[k0 - self._truth_k0:k0 - self._truth_k0 + len(rows_kept)] = rows_kept
        return dict(zip(self.truth_channels(), states.T))

    def true_convection_resistance(self, engine_rpm: float, clutch_state: int) -> float:
        """R_FA = R_PA of eq. (11) at an operating point: the paper plant's own; NaN for a plant without one."""
        from benchlab.model.clutch import convection_resistance

        if self.plant_name != "paper":
            return math.nan
        ch = {"engine_speed": np.array([float(engine_rpm)]), "clutch_state": np.array([float(clutch_state)])}
        return float(np.asarray(convection_resistance(self.truth_params, ch)).ravel()[0])


_ACTUAL_SOURCES = ("engine_speed", "clutch_speed", "clutch_torque", "friction_power", "clutch_state", "load_torque")


@njit(cache=True, nogil=True)
def grid_index(t: float, dt: float) -> int:  # pragma: no cover - compiled
    """The grid point a time falls on (the one at or before it, 1e-6 of a step of slack for rounding)."""
    return int(math.floor(t / dt + 1e-6))


@njit(cache=True, nogil=True)
def _grid_rows(times: np.ndarray, dt: float, k0: int, matrix: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Rows of `matrix` (grid points from k0 on) at the grid point of each of `times`."""
    rows = np.empty((times.shape[0], matrix.shape[1]))
    for i in range(times.shape[0]):
        row = grid_index(times[i], dt) - k0
        for j in range(matrix.shape[1]):  # element by element: a row assignment compiles numba's shape-mismatch error
            rows[i, j] = matrix[row, j]
    return rows


@njit(cache=True, nogil=True)
def _measured(rows: np.ndarray, stroke_mm: float, gear: float) -> np.ndarray:  # pragma: no cover - compiled
    """DrivetrainActuals' fields (7, n) from rows of _ACTUAL_SOURCES + speed noise (2) + torque noise: noise added
    where a sensor measures, clamp state from the clutch state and friction, torque and speeds not below 0."""
    out = np.empty((7, rows.shape[0]))
    for i in range(rows.shape[0]):
        _measure(rows[i], stroke_mm, gear, out, i)
    return out


@njit(cache=True, nogil=True)
def _measured_at(times: np.ndarray, dt: float, k0: int, matrix: np.ndarray, stroke_mm: float,
                 gear: float) -> np.ndarray:  # pragma: no cover - compiled
    """`_measured` of the rows of `matrix` (grid points from k0 on) at the grid point of each of `times`."""
    out = np.empty((7, times.shape[0]))
    for i in range(times.shape[0]):
        _measure(matrix[grid_index(times[i], dt) - k0], stroke_mm, gear, out, i)
    return out


@njit(cache=True, nogil=True)
def _measure(row: np.ndarray, stroke_mm: float, gear: float, out: np.ndarray, i: int) -> None:  # pragma: no cover
    """Column i of `_measured` from one row."""
    is_clamped = row[4] >= 0.5
    torque_abs = abs(row[2])
    out[0, i] = row[0] + row[6]
    out[1, i] = row[2]
    out[2, i] = max(0.0, torque_abs + row[8]) if torque_abs > 0 else 0.0
    out[3, i] = 0.0 if is_clamped else stroke_mm
    out[4, i] = (CLAMP_SLIPPING if row[3] > 0.0 else CLAMP_CLAMPED) if is_clamped else CLAMP_OPEN
    out[5, i] = max(0.0, row[1] + row[7]) / gear
    out[6, i] = row[5]


class SimBench:
    """The emulated devices on their transports, fed by `SimPhysics`; `service()` runs them up to now."""

    def __init__(self, config: SimBenchConfig = SimBenchConfig(), clock: SimClock | None = None,
                 plant: ThermalPlant | None = None, faults: Sequence[Any] = ()) -> None:
        self.cfg = config
        self.injected = tuple(faults)  # as given, for the run file's sim_faults
        self.faults = sorted(faults, key=lambda f: f.at_s)  # still to apply, in time order
        self.faults_applied: list[Any] = []
        self.clock = clock or SimClock(config.t0)
        self.physics = SimPhysics(config, self.clock, plant)
        name = f"benchlab-sim-{next(_ids)}"
        self.name = name
        self.dmm = ScpiInstrumentEmulator(self.physics, clock=self.clock)
        self.node = ClutchNodeEmulator(self.physics, period_s=config.node_period_s, clock=self.clock)
        registry.register(f"{name}-dmm", self.dmm)
        registry.register(f"{name}-node", self.node)
        # the drivers' bus and the controllers' bus: one in-process channel stamped with the simulated clock
        self.emulator_bus = SimCanBus(f"{name}-can", clock=self.clock)
        self.driver_bus = SimCanBus(f"{name}-can", clock=self.clock)
        self.can = CanBenchEmulator(self.emulator_bus, self.physics, clock=self.clock)
        s = config.sensors
        self._dropout_rate = s.dropouts_per_hour / 3600.0 if config.dropouts else 0.0
        self._next_dropout = self._draw_next(self.clock())
        # the emulators' kernels compiled (or loaded from numba's cache) before any driver talks to them: a compile
        # inside a real-time run silences the emulated controllers past the driver's limit (the physics' own
        # kernels were primed by SimPhysics)
        for module in (can_controllers, clutch_node, sim_can_bus):
            module.prime()

    @property
    def urls(self) -> dict[str, str]:
        return {"instrument": f"sim://{self.name}-dmm", "node": f"sim://{self.name}-node"}

    def run_attrs(self) -> dict[str, str]:
        """The run file's attributes that describe this bench (docs/runfile.md): `sim_bench` (its configuration),
        `sim_faults` (the faults injected) and `sim_truth` (the plant's true parameters and hidden effects)."""
        effects = [e.name for e in self.physics.plant.effects if not e.name.startswith("fault heater")]
        return {"sim_bench": json.dumps(self.cfg.as_dict(), default=str),
                "sim_faults": json.dumps([asdict(fault) for fault in self.injected]),
                "sim_truth": json.dumps({"params": dict(self.physics.truth_params), "effects": effects,
                                         "plant": self.physics.plant_name})}

    def truth_units(self) -> dict[str, str]:
        """The run file's /truth columns (the plant's true temperatures) with their units."""
        return {name: "degC" for name in self.physics.truth_channels()}

    def record_truth_into(self, sink: Callable[[int, np.ndarray], None]) -> None:
        """The plant's true states go to `sink` (first grid row, (n, columns) in `truth_units`' order) once final,
        the rest when the run ends (`hand_over_truth`): a run file's /truth written as it goes."""
        self.physics.truth_sink = sink

    def hand_over_truth(self) -> None:
        """The true states not final yet to the sink: the run ends."""
        self.physics.hand_over_truth()

    def _draw_next(self, t: float) -> float:
        if self._dropout_rate <= 0:
            return math.inf
        return t + float(self.physics.rng_dropout.exponential(1.0 / self._dropout_rate))

    def service(self) -> None:
        """Before the drivers poll: start due radio drop-outs, let the controllers take commands and report."""
        now = self.clock()
        self.can.poll()  # first: the controllers take the commands sent since the last poll at their times
        while self.faults and now >= self.faults[0].at_s:
            fault = self.faults.pop(0)
            fault.apply(self)
            self.faults_applied.append(fault)
        while now >= self._next_dropout:
            mean = self.cfg.sensors.dropout_mean_s
            length = min(float(self.physics.rng_dropout.exponential(mean)), MAX_DROPOUT_MEANS * mean)
            self.node.radio_silence(max(length, self.cfg.node_period_s) - (now - self._next_dropout))
            self._next_dropout = self._draw_next(self._next_dropout)

    def close(self) -> None:
        registry.unregister(f"{self.name}-dmm")
        registry.unregister(f"{self.name}-node")
        for bus in (self.emulator_bus, self.driver_bus):
            try:
                bus.shutdown()
            except Exception:  # noqa: BLE001 - closing twice is fine
                pass


@dataclass(frozen=True)
class SimulatedBench:
    """The simulated bench a run asks for (`RunRequest.bench`; the string "sim" is the default one): the plant,
    the faults to inject, `SimBenchConfig` overrides and the limits (a hardware bench's come from BENCH.toml).

    The runner asks it for its `bench_config()` before anything moves and `open()`s it when the run starts, so
    the runner never names the simulator's fields and the hardware path never imports the simulator.
    """

    plant: ThermalPlant | None = None  # None: the reference clutch (sim_bench.reference_plant); the paper's: ThermalPlant()
    faults: Sequence[Fault] = ()  # sim_bench.faults.Fault, applied when the clock passes their at_s
    options: Mapping[str, Any] = field(default_factory=dict)  # SimBenchConfig overrides, e.g. {"dropouts": False}
    limits: BenchLimits = BenchLimits()
    realtime: float | None = None  # pace simulated time at this factor x real time (SimClock's pace); None: flat out
    name: ClassVar[str] = "sim"  # the run file's `bench` attribute and the CLI's --bench

    def __post_init__(self) -> None:
        object.__setattr__(self, "faults", tuple(self.faults))  # a list given stays the caller's

    def bench_config(self) -> BenchConfig:
        """The runner's view of this bench: limits, acquisition timing, CAN stamped on the run clock; the device
        addresses are placeholders until `open` knows them."""
        from benchlab.runner.devices import BenchConfig

        return BenchConfig(instrument_url="sim://pending", node_url="sim://pending", can={"interface": "sim"},
                           can_timestamps="run", instrument_timeout_s=0.05, limits=self.limits, source="sim",
                           tick_s=1.0, fast_tick_s=0.05, instrument_period_s=0.5)

    def open(self, config: BenchConfig, seed: int, t0: float = 0.0,
             initial_c: float | Mapping[str, float] | None = None) -> tuple[SimBench, BenchConfig]:
        """The emulated devices on `config`'s grid and drivetrain, from `t0` (a resume) with `seed`, and `config`
        with their addresses; the caller closes the SimBench."""
        cfg = SimBenchConfig(seed=seed, dt=config.dt, t0=t0, drivetrain=config.drivetrain, initial_c=initial_c,
                             **dict(self.options))
        sim = SimBench(cfg, clock=SimClock(t0, pace=self.realtime), plant=self.plant, faults=self.faults)
        return sim, replace(config, instrument_url=sim.urls["instrument"], node_url=sim.urls["node"],
                            can={"interface": "sim", "channel": sim.name + "-can"})
