"""The observer over a whole run (`benchlab observe`): every state estimated at every sample, with its spread."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.model.clutch import clutch_network
from benchlab.errors import InputError
from benchlab.network import Params, ThermalNetwork
from benchlab.observer.consistency import Consistency, innovation_consistency
from benchlab.observer.kalman import filter_run
from benchlab.observer.model import ObserverModel, Reset
from benchlab.observer.noise import NoiseModel, tune_noise
from benchlab.observer.observability import Observability, analyse
from benchlab.network.simulation import initial_state, input_channels
from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.model import wear_history
from benchlab.wear.thermal import heat_split

STD_SUFFIX = "_std"


@dataclass(frozen=True)
class Observation:
    """Estimates (state channel names, degC; law corrections, K/W) with their standard deviations (`<name>_std`),
    and how they came about: observability, the model with its sensors and noise, the starting estimate."""

    estimate: pd.DataFrame
    observability: Observability
    model: ObserverModel
    initial: np.ndarray  # the filter's starting estimate, degC, per state
    consistency: tuple[Consistency, ...] = ()  # per sensor: does the spread hold its innovations (NIS)?

    @property
    def noise(self) -> NoiseModel:
        return self.model.noise


def sensor_readings(run: pd.DataFrame, channels: Sequence[str], what: str = "--sensors") -> np.ndarray:
    """(N, sensors) readings as measured, NaN kept (skipped by the filter); InputError for a channel the run lacks."""
    source = run.attrs.get("source", "<run>")
    for channel in channels:
        if channel not in run.columns:
            raise InputError(source, f"/aligned/{channel}", f"the channel {what} names (the run has none)")
    if not channels:
        return np.zeros((len(run), 0))
    return np.column_stack([run[c].to_numpy(np.float64) for c in channels])


def fresh(readings: np.ndarray) -> np.ndarray:
    """Each reading once: a sample repeating the previous sample's value is the grid holding a slower sensor's
    reading (a scanner every 0.5 s is 50 equal samples), not a new measurement, and becomes NaN. Fed 50 times,
    one reading's noise would count as 50 independent ones and the band would shrink √50-fold below the truth."""
    out = readings.copy()
    out[1:][readings[1:] == readings[:-1]] = np.nan
    return out


def reset_values(run: pd.DataFrame, resets: Sequence[Reset]) -> np.ndarray:
    """(N, resets): each reset's reading at the first sample at or after its time that has one, NaN elsewhere."""
    source = run.attrs.get("source", "<run>")
    readings = sensor_readings(run, [r.channel for r in resets], "--reinit")
    out = np.full(readings.shape, np.nan)
    dt = float(run.attrs["dt"])
    for j, reset in enumerate(resets):
        first = int(np.ceil(reset.time_s / dt - 1e-9))
        valid = np.flatnonzero(np.isfinite(readings[first:, j])) + first if first < len(run) else np.array([])
        if valid.size == 0:
            raise InputError(source, f"--reinit {reset.channel}@{reset.time_s:g}",
                             f"a reading of {reset.channel} at or after {reset.time_s:g} s (the run has none)")
        out[valid[0], j] = readings[valid[0], j]
    return out


def observe(run: pd.DataFrame, params: Params, sensors: Sequence[str], network: ThermalNetwork | None = None,
            resets: Sequence[Reset] = (), initial_offset_k: float = 0.0, noise: NoiseModel | None = None,
            adapt: Sequence[str] = ()) -> Observation:
    """Filter the run: each state starts where `simulate` starts it plus `initial_offset_k`, is updated with the
    readings of `sensors` (NaN skipped) and re-initialised by `resets`; the laws of the links `adapt` are
    corrected online. Estimate and spread at every sample."""
    network = network or clutch_network()
    source = run.attrs.get("source", "<run>")
    channels = input_channels(run)
    measured = sensor_readings(run, sensors)
    dt = float(run.attrs["dt"])
    noise = noise or tune_noise(network, params, [*sensors, *(r.channel for r in resets)], initial_offset_k)
    model = ObserverModel(network, params, sensors, noise, resets, adapt)
    readings = model.temperatures(fresh(measured), np.arange(len(run)) * dt)
    x0 = initial_state(network, channels, source, params=params) + initial_offset_k
    disc = model.discretise(channels, dt)
    samples = len(run)
    resistances = model.resistances(channels, samples)
    z0 = np.concatenate([x0, np.zeros(len(model.adapted))])
    out_z, out_std = np.empty((samples, len(z0))), np.empty((samples, len(z0)))
    filter_run(disc.op_index, disc.Ad, disc.Bd, disc.inputs, model.process_variance(dt), resistances, model.S,
               model.T, model.correction_variance(resistances[0], dt), dt, readings, model.sensor_state,
               model.sensor_var, model.temperatures(reset_values(run, model.resets), np.arange(samples) * dt,
                                                    [r.channel for r in model.resets]), model.reset_state, model.reset_var, z0,
               model.initial_covariance(resistances[0]), out_z, out_std)
    columns = {}
    for i, name in enumerate([model.names[s] for s in model.states] + model.adapted):
        columns[name] = out_z[:, i]
        columns[name + STD_SUFFIX] = out_std[:, i]
    names = tuple(model.names[s] for s in model.states)
    seen = analyse(disc.op_index, disc.Ad, model.sensor_state, measured, model.sensors, names)
    consistency = innovation_consistency(model.sensors, readings, out_z[:, model.sensor_state],
                                         out_std[:, model.sensor_state], model.sensor_var, dt)
    return Observation(pd.DataFrame(columns, index=run.index), seen, model, x0, tuple(consistency))


#: Units of the wear channels written beside the estimates.
WEAR_UNITS = {"wear_plate_mm": "mm", "wear_flywheel_mm": "mm", "loss_plate": "1", "loss_flywheel": "1"}


def estimated_wear(run: pd.DataFrame, observation: Observation, params: Params, clutch: ClutchSpec
                   ) -> dict[str, np.ndarray] | None:
    """Eq. (3) over the run at the estimated plate and flywheel temperatures, cumulative per sample (the online
    wear's integral); None for a model without those two states."""
    estimate = observation.estimate
    if not {"T_pressure_plate", "T_flywheel"} <= set(estimate.columns):
        return None
    power = input_channels(run)["friction_power"]
    history = wear_history(clutch, power, heat_split(params), estimate["T_pressure_plate"].to_numpy(),
                           estimate["T_flywheel"].to_numpy(), float(run.attrs["dt"]))
    return history.cumulative
