"""A thermal network made ready for filtering: a noise heat flow on every node, sensors and resets mapped to states.

Shared by the batch filter (`benchlab observe`) and the online one, so both see the same model: the network's
own inputs (heat sources, then boundary temperatures) come first in Bd, the process-noise heat flows after them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from benchlab.errors import InputError
from benchlab.network import (Channels, ParamChannelFunction, Params, Source, ThermalNetwork, as_samples, sample_matrix,
                              state_channels)
from benchlab.network.sensors import coefficients, temperature_of
from benchlab.observer.noise import ADAPT_DRIFT, ADAPT_INITIAL, NoiseModel
from benchlab.network.solver import Discretised, conductance_matrices, discretise


def _no_heat(params: Params, channels: Channels) -> float:
    """The law of a process-noise source: zero in the model, its spread enters through the covariance."""
    return 0.0


@dataclass(frozen=True)
class Reset:
    """Re-initialise the state `channel` measures from its reading at `time_s` (the first one with a number)."""

    channel: str
    time_s: float


class ObserverModel:
    """Network, parameters, sensors (observer inputs), resets and noise, checked; discretises runs for the filter."""

    def __init__(self, network: ThermalNetwork, params: Params, sensors: Sequence[str], noise: NoiseModel,
                 resets: Sequence[Reset] = (), adapt: Sequence[str] = (), source: str = "--sensors") -> None:
        network.validate()
        self.network, self.params, self.noise = network, params, noise
        self.states = network.state_names
        self.names = state_channels(network)  # state -> channel name in files and figures
        index = {s: i for i, s in enumerate(self.states)}
        readable = ", ".join(sorted(network.outputs))
        for channel in [*sensors, *(r.channel for r in resets)]:
            if channel not in network.outputs:
                raise InputError(source, channel, f"a channel the model predicts ({readable})")
        self.sensors = tuple(dict.fromkeys(sensors))
        self.resets = tuple(resets)
        self.sensor_state = np.array([index[network.outputs[c]] for c in self.sensors], dtype=np.int64)
        self.reset_state = np.array([index[network.outputs[r.channel]] for r in self.resets], dtype=np.int64)
        # a calibrated sensor's reading is handed to the filter as the temperature it stands for (`temperatures`),
        # its noise divided by the gain: an exact rescaling of a scalar update
        self.sensor_var = np.array([(noise.sensor_k[c] / self._gain(c)) ** 2 for c in self.sensors])
        self.reset_var = np.array([(noise.sensor_k[r.channel] / self._gain(r.channel)) ** 2 for r in self.resets])
        self.nodes = [node.name for node in network.nodes]
        self._noisy = replace(network, sources=network.sources + tuple(
            Source(node, _no_heat, f"process noise {node}") for node in self.nodes))
        n_src, n_noise = len(network.sources), len(self.nodes)
        n_in = n_src + n_noise + len(network.boundaries)
        noise_cols = list(range(n_src, n_src + n_noise))
        self._real = [c for c in range(n_in) if c not in noise_cols]
        self._order = self._real + noise_cols  # Bd columns: the network's inputs, then the noise heat flows
        self.m = len(self._real)
        self._adapt_laws: list[ParamChannelFunction] = []  # one correction per law: R_PA and R_FA share eq. 11
        self.adapted: list[str] = []  # its name in files: `<link>_correction` (K/W)
        for label in adapt:
            link = next((k for k in network.links if k.label == label), None)
            if link is None:
                labels = ", ".join(k.label for k in network.links if k.label)
                raise InputError("--adapt", label, f"a link of the model ({labels})")
            if any(link.resistance is law for law in self._adapt_laws):
                continue
            self._adapt_laws.append(link.resistance)
            self.adapted.append(f"{label}_correction")
        pairs = [conductance_matrices(network, params, [i for i, k in enumerate(network.links) if k.resistance is law])
                 for law in self._adapt_laws]
        self.S = np.array([p[0] for p in pairs]).reshape(len(pairs), len(self.states), len(self.states))
        self.T = np.array([p[1] for p in pairs]).reshape(len(pairs), len(self.states), self.m)

    def process_variance(self, dt: float) -> np.ndarray:
        """Variance (W²) of each node's noise heat flow held over one sample of `dt`: density² / dt."""
        return np.array([self.noise.heat_flow_w[node] ** 2 / dt for node in self.nodes])

    def resistances(self, channels: Mapping[str, np.ndarray], samples: int) -> np.ndarray:
        """(samples, adapted laws): each adapted law's resistance (K/W) at every sample, before correction."""
        columns = [as_samples(law(self.params, channels), samples) for law in self._adapt_laws]
        return sample_matrix(columns, samples)

    def initial_covariance(self, first_resistances: np.ndarray) -> np.ndarray:
        """P0: the noise model's spread on every temperature, ADAPT_INITIAL of the law's first resistance on each
        correction."""
        spread = np.concatenate([np.full(len(self.states), self.noise.initial_k),
                                 ADAPT_INITIAL * np.asarray(first_resistances)])
        return np.diag(spread ** 2)

    def correction_variance(self, first_resistances: np.ndarray, dt: float) -> np.ndarray:
        """Variance added to each correction per sample: a random walk of ADAPT_DRIFT of its resistance per √s."""
        return (ADAPT_DRIFT * np.asarray(first_resistances)) ** 2 * dt

    def _gain(self, channel: str) -> float:
        """The gain of the channel's sensor (1 where it has no calibration)."""
        return coefficients(self.network.calibrations.get(channel), self.params)[0]

    def temperatures(self, readings: np.ndarray, seconds: "float | np.ndarray",
                     channels: Sequence[str] | None = None) -> np.ndarray:
        """Readings of `channels` (default the sensors; samples × channels, or one sample's) as the temperatures of
        the states they read, `seconds` since the run's first sample (benchlab.network.sensors.temperature_of)."""
        if not self.network.calibrations:
            return readings
        out = np.array(readings, dtype=np.float64)
        for j, channel in enumerate(self.sensors if channels is None else channels):
            out[..., j] = temperature_of(self.network.calibrations.get(channel), self.params, out[..., j], seconds)
        return out

    def discretise(self, channels: Mapping[str, np.ndarray], dt: float) -> Discretised:
        """Ad, Bd per operating point with Bd = [network inputs | noise columns Γ]; inputs without noise columns."""
        disc = discretise(self._noisy, self.params, channels, dt)
        return Discretised(disc.op_index, disc.Ad, np.ascontiguousarray(disc.Bd[:, :, self._order]),
                           np.ascontiguousarray(disc.inputs[:, self._real]))
