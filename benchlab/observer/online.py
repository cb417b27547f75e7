"""The observer one sample at a time, as a transmission control unit runs it every 10 ms, carrying online wear.

`step(inputs, measurement)` takes this sample's input channels (the operating point and the heat input) and
readings (NaN where a sensor has none), updates, hands back the estimate at this sample, and predicts the next.
The discrete matrices of an operating point are made the first time it is met and kept: the point is the
values of the channels the network's resistance laws and temperature terms read (found by watching the laws), each rounded to a
quantum (engine speed to 1 rpm: at most 0.1 % of the paper's convection resistance, far below what the sensors
resolve). The filter arithmetic is the compiled step of `benchlab.observer.kalman`, the same as the batch
filter's; the wear is `benchlab.wear.online.LiningWear`, fed with the estimated plate and flywheel temperatures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from benchlab.model.clutch import clutch_network
from benchlab.errors import InputError
from benchlab.network import Params, ThermalNetwork
from benchlab.network.structure import sequential_laws
from benchlab.observer.kalman import filter_step, reinitialise
from benchlab.observer.model import ObserverModel
from benchlab.observer.noise import NoiseModel, tune_noise
from benchlab.runfile import ALIGNED_UNITS
from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.online import LiningWear
from benchlab.wear.thermal import heat_split

#: Operating-point quantum per channel unit (speeds, clutch state, powers, torques, temperatures).
QUANTUM_BY_UNIT = {"rpm": 1.0, "1": 1.0, "W": 1.0, "N*m": 0.1, "degC": 0.01}
#: Quantum of a channel whose unit is not known.
DEFAULT_QUANTUM = 1e-3
#: The channels that carry the wear: plate and flywheel temperatures, friction power.
WEAR_CHANNELS = ("T_pressure_plate", "T_flywheel", "friction_power")


def quantum_of(channel: str, quantum: Mapping[str, float] | None = None) -> float:
    """The operating-point quantum of a channel: the caller's, else by its unit in the contract (QUANTUM_BY_UNIT)."""
    given = (quantum or {}).get(channel)
    return float(given if given is not None else
                 QUANTUM_BY_UNIT.get(ALIGNED_UNITS.get(channel, ""), DEFAULT_QUANTUM))


class Estimate(NamedTuple):
    """Estimate at one sample: temperature (degC) and std (K) per state in `OnlineObserver.states` order, each
    adapted law's resistance correction (K/W) and its std, and the wear [s_P, s_F, δ_P, δ_F] (mm per face,
    fraction) or None. Overwritten by the next step: copy to keep."""

    temperature: np.ndarray
    std: np.ndarray
    correction: np.ndarray
    correction_std: np.ndarray
    wear: list[float] | None


class _Watched(dict):
    """Channels for a law, noting which ones it reads."""

    def __init__(self, values: Mapping[str, Any]) -> None:
        super().__init__(values)
        self.read: set[str] = set()

    def __getitem__(self, key: str) -> Any:
        self.read.add(key)
        return super().__getitem__(key)


class OnlineObserver:
    """Kalman observer of any thermal network, sample by sample; states, sensors and inputs are fixed at creation."""

    def __init__(self, params: Params, sensors: Sequence[str], inputs: Sequence[str], x0: Sequence[float],
                 dt: float, network: ThermalNetwork | None = None, noise: NoiseModel | None = None,
                 clutch: ClutchSpec | None = None, quantum: Mapping[str, float] | None = None,
                 adapt: Sequence[str] = ()) -> None:
        network = network or clutch_network()
        switched = sequential_laws(network)
        if switched:  # stepped a sample at a time, a switch would start afresh at each one
            raise InputError("model", ", ".join(switched), "a law without hysteresis(...): the online observer does "
                             "not carry a switch's state from sample to sample yet (docs/deploy.md)")
        noise = noise or tune_noise(network, params, list(network.outputs))
        self.model = ObserverModel(network, params, sensors, noise, adapt=adapt)
        self.states = [self.model.names[s] for s in self.model.states]
        self.sensors = self.model.sensors
        self.inputs = tuple(inputs)
        self.dt = float(dt)
        self._quantum = {c: quantum_of(c, quantum) for c in self.inputs}
        n, na = len(self.states), len(self.model.adapted)
        if len(x0) != n:
            raise InputError("x0", "initial state", f"{n} temperatures ({', '.join(self.states)}), got {len(x0)}")
        self.z = np.concatenate([np.asarray(x0, dtype=np.float64), np.zeros(na)])  # temperatures, corrections
        self.P = np.eye(n + na) * noise.initial_k ** 2  # the corrections' spread is set at the first sample
        self._qd = np.zeros(na)
        self._q = self.model.process_variance(self.dt)
        self._u = np.zeros(self.model.m)
        self._out = np.zeros((2, n + na))
        self._scratch = np.zeros((n + na, 2 * (n + na) + 2))
        self._laws = [lambda ch, law=s.heat_flow: law(params, ch) for s in network.sources]
        self._laws += [b.temperature for b in network.boundaries]
        self._held: Sequence[float] | None = None  # the last sample's inputs
        self._samples = 0  # samples stepped: a calibrated sensor's drift is in K per second of the run
        self._key_channels: tuple[str, ...] = ()
        self._key_index: list[tuple[int, float]] = []  # (position in inputs, 1 / quantum) per key channel
        self._points: dict[Any, tuple[np.ndarray, np.ndarray]] = {}  # key -> ([Ad | Bd], adapted resistances)
        self.lining: LiningWear | None = None
        if clutch is not None:
            missing = [c for c in WEAR_CHANNELS[:2] if c not in self.states] + \
                      [c for c in WEAR_CHANNELS[2:] if c not in self.inputs]
            if missing:
                raise InputError("clutch", "wear", f"a model with plate and flywheel states and friction_power "
                                                   f"among the inputs (missing {', '.join(missing)})")
            self.lining = LiningWear(clutch, self.dt, heat_split(params))
            self._plate, self._flywheel = self.states.index(WEAR_CHANNELS[0]), self.states.index(WEAR_CHANNELS[1])
            self._power = self.inputs.index(WEAR_CHANNELS[2])
        self._estimate = Estimate(self._out[0, :n], self._out[1, :n], self._out[0, n:], self._out[1, n:],
                                  self.lining.wear if self.lining else None)

    @property
    def operating_points(self) -> int:
        """Operating points met so far (each one discretised once)."""
        return len(self._points)

    def _key(self, inputs: Sequence[float]) -> tuple[int, ...]:
        """The operating point of a sample: its resistance-law channels in quanta."""
        return tuple([round(inputs[i] * inverse) for i, inverse in self._key_index])

    def _point(self, channels: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """[Ad | Bd] and the adapted laws' resistances of a new operating point; learns which channels the
        resistance laws read."""
        watched = _Watched({c: np.array([v], dtype=np.float64) for c, v in channels.items()})
        try:
            for link in self.model.network.links:
                link.resistance(self.model.params, watched)
            for source in self.model.network.sources:  # a temperature term's W/K goes into Ad too (copper loss)
                for _, law in source.coefficients:
                    law(self.model.params, watched)
        except KeyError as exc:
            raise InputError("inputs", str(exc.args[0]), "an input channel the model's laws need") from None
        new = tuple(sorted(watched.read - set(self._key_channels)))
        if new:  # a law reads a channel not seen before: the points made so far are keyed too coarsely
            self._key_channels += new
            self._key_index = [(self.inputs.index(c), 1.0 / self._quantum[c]) for c in self._key_channels]
            self._points.clear()
        key = self._key([channels[c] for c in self.inputs])
        point = {c: np.array([k * self._quantum[c]]) for c, k in zip(self._key_channels, key)}
        at = {**{c: np.array([v]) for c, v in channels.items()}, **point}
        disc = self.model.discretise(at, self.dt)
        entry = (np.ascontiguousarray(np.concatenate([disc.Ad[0], disc.Bd[0]], axis=1)),
                 self.model.resistances(at, 1)[0])
        if self._held is None:  # the first sample: the corrections' spread and drift scale with their laws
            n = len(self.states)
            self.P[n:, n:] = self.model.initial_covariance(entry[1])[n:, n:]
            self._qd[:] = self.model.correction_variance(entry[1], self.dt)
        self._points[key] = entry
        return entry

    def step(self, inputs: Sequence[float], measurement: "Sequence[float] | np.ndarray") -> Estimate:
        """This sample's inputs (in `inputs` order) and readings (in `sensors` order) -> the estimate at this
        sample; the state moves on to the next sample. A sensor without a new reading this sample gives NaN: a
        reading fed again on later samples would count its noise as new information each time."""
        if isinstance(inputs, np.ndarray):  # Python floats: numpy scalars make every law several times slower
            inputs = inputs.tolist()
        if math.isnan(sum(inputs)):
            inputs = self._hold(inputs)
        channels = dict(zip(self.inputs, inputs))
        point = self._points.get(self._key(inputs))
        if point is None:
            point = self._point(channels)
        self._held = inputs
        u = self._u
        for i, law in enumerate(self._laws):
            u[i] = law(channels)
        model = self.model
        readings = model.temperatures(np.asarray(measurement, dtype=np.float64), self._samples * self.dt)
        self._samples += 1
        filter_step(point[0], u, self._q, point[1], model.S, model.T, self._qd, self.dt,
                    readings, model.sensor_state, model.sensor_var, self.z, self.P,
                    self._out, self._scratch)
        if self.lining is not None:
            estimate = self._out[0]
            self.lining.add(inputs[self._power], float(estimate[self._plate]), float(estimate[self._flywheel]))
        return self._estimate

    def _hold(self, inputs: Sequence[float]) -> list[float]:
        """An input without a number keeps its last one (zero-order hold, as between samples)."""
        if self._held is None:
            missing = [c for c, v in zip(self.inputs, inputs) if math.isnan(v)]
            raise InputError("inputs", ", ".join(missing), "a number at the first sample (nothing to hold)")
        return [v if not math.isnan(v) else last for v, last in zip(inputs, self._held)]

    def reinitialise(self, channel: str, value: float) -> None:
        """Set the state `channel` reads to `value` from the next sample on (an engine start, a long stop: the
        paper's oil-temperature case), with the channel's reading noise as its spread."""
        if channel not in self.model.network.outputs:
            raise InputError("reinitialise", channel, f"a channel the model predicts "
                                                      f"({', '.join(sorted(self.model.network.outputs))})")
        state = self.model.states.index(self.model.network.outputs[channel])
        variance = self.model.noise.sensor_k[channel] ** 2
        reinitialise(self.z, self.P, state, float(value), variance)
