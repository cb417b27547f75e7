"""The observer's noise: a heat-flow noise on each node, a reading noise per sensor, the initial spread.

Tuned from the identification's residuals where the parameter file has them (`benchlab identify` stores each
fitting run's full-rate RMS error per channel under "fit"), else the documented defaults below:

* a sensor's reading noise is its channel's residual RMS r (sensor noise plus whatever the model misses there);
* a node's heat-flow noise density q (W·√s) is the one that would, alone, make the node wander by r about the
  model: a node of capacity C losing heat through a total conductance G settles at a variance q²/(2·C·G) under
  white heat-flow noise, so q = r·√(2·C·G), G taken at the parked operating point (every channel 0: engine
  off, clutch open), the node's slowest; a node no channel reads (the plate) takes the largest r of the
  channels that have one. Never below DEFAULT_HEAT_FLOW_W.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchlab.errors import InputError
from benchlab.network import Params, ThermalNetwork
from benchlab.values import positive_number

#: Reading noise of a sensor without residual statistics (K, 1σ): a PT1000 read by a scanner or the node.
DEFAULT_SENSOR_K = 0.1
#: Heat-flow noise density of a node without residual statistics, and the least any node gets (W·√s: the std of
#: the heat flow the model misses, averaged over one second): about the noise of the measured friction power
#: (0.2 N·m of torque noise at 150 rad/s of slip is 30 W per 10 ms sample, 3 W·√s).
DEFAULT_HEAT_FLOW_W = 3.0
#: Spread of every state at the start (K, 1σ), for a start from the first readings (plate = flywheel). A start
#: moved by --initial-offset K is a start known to within |K|: the spread is then at least |K|.
DEFAULT_INITIAL_K = 2.0
#: A law corrected online (`--adapt`): its resistance offset starts at 0 with this spread, relative to the law's
#: resistance at the first sample (an identification can be a fifth off, the paper's R0 among the hardest), ...
ADAPT_INITIAL = 0.25
#: ... and may drift as a random walk by this share of it per √s (0.3 %: a tenth of it in about twenty minutes).
ADAPT_DRIFT = 3e-3


@dataclass(frozen=True)
class NoiseModel:
    """Process noise per node (W·√s), reading noise per sensor channel (K), initial spread (K); `origin` says
    where the numbers came from."""

    heat_flow_w: Mapping[str, float]
    sensor_k: Mapping[str, float]
    initial_k: float
    origin: str

    def as_dict(self) -> dict[str, Any]:
        return {"heat_flow_W_sqrt_s": dict(self.heat_flow_w), "sensor_K": dict(self.sensor_k),
                "initial_K": self.initial_k, "origin": self.origin}


def check_positive(source: str, field: str, value: float, unit: str) -> float:
    """A noise figure must be a positive finite number: InputError naming the field otherwise."""
    number = positive_number(value)
    if number is None:
        raise InputError(source, field, f"a positive noise in {unit}, got {value!r}")
    return number


def with_overrides(noise: NoiseModel, heat_flow_w: float | None = None, sensor_k: Mapping[str, float] | None = None,
                   initial_k: float | None = None, source: str = "command line") -> NoiseModel:
    """The noise model with figures given by the user (each checked positive) in place of the tuned ones."""
    heat = dict(noise.heat_flow_w)
    if heat_flow_w is not None:
        heat = {n: check_positive(source, "--process-noise", heat_flow_w, "W*sqrt(s)") for n in heat}
    sensors = dict(noise.sensor_k)
    for channel, value in (sensor_k or {}).items():
        sensors[channel] = check_positive(source, f"--sensor-noise {channel}", value, "K")
    initial = noise.initial_k if initial_k is None else check_positive(source, "--initial-std", initial_k, "K")
    changed = heat_flow_w is not None or bool(sensor_k) or initial_k is not None
    return NoiseModel(heat, sensors, initial, noise.origin + (", command-line values" if changed else ""))


def residual_rms(extra: Mapping[str, Any], channel: str) -> float | None:
    """The full-rate RMS error of `channel` over the identification's fitting runs (None without statistics)."""
    fit = extra.get("fit")
    fitting = fit.get("fitting") if isinstance(fit, Mapping) else None
    values = []
    for run in (fitting.values() if isinstance(fitting, Mapping) else ()):
        value = run.get("channels", {}).get(channel, {}).get("rmse_K") if isinstance(run, Mapping) else None
        number = positive_number(value)
        if number is not None:
            values.append(number)
    return float(np.sqrt(np.mean(np.square(values)))) if values else None


class _Parked(dict):
    """Every channel a law asks for reads 0 (one sample): the parked operating point."""

    def __missing__(self, key: str) -> np.ndarray:
        return np.zeros(1)


def parked_conductance(network: ThermalNetwork, params: Params) -> dict[str, float]:
    """Each node's total conductance (W/K) at the parked operating point; a law without a finite positive
    resistance there is left out."""
    total = {node.name: 0.0 for node in network.nodes}
    for link in network.links:
        with np.errstate(all="ignore"):
            r = np.asarray(link.resistance(params, _Parked()), dtype=np.float64).ravel()
        if r.size and np.isfinite(r[0]) and r[0] > 0:
            for end in (link.a, link.b):
                if end in total:
                    total[end] += 1.0 / float(r[0])
    return total


def tune_noise(network: ThermalNetwork, params: Params, channels: Sequence[str], initial_offset_k: float = 0.0
               ) -> NoiseModel:
    """Noise from the parameter file's residual statistics where it has them, else the defaults (module doc);
    `channels` are the sensors (and re-initialising channels) to give a reading noise."""
    extra = getattr(params, "extra", {}) or {}
    residuals = {c: residual_rms(extra, c) for c in network.outputs}
    known = [r for r in residuals.values() if r is not None]
    sensor = {c: residuals.get(c) or DEFAULT_SENSOR_K for c in channels}
    reading = {state: residuals[c] for c, state in network.outputs.items() if residuals[c] is not None}
    conductance = parked_conductance(network, params)
    heat = {}
    for node in network.nodes:
        r = reading.get(node.name, max(known) if known else None)
        q = r * math.sqrt(2.0 * params[node.capacity] * conductance[node.name]) if r is not None else 0.0
        heat[node.name] = max(DEFAULT_HEAT_FLOW_W, q)
    origin = "identification residuals" if known else "defaults (the parameter file has no residual statistics)"
    return NoiseModel(heat, sensor, float(max(DEFAULT_INITIAL_K, abs(initial_offset_k))), origin)
