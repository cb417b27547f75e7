"""Sensors as a design choice: what a temperature sensor at each place of the model (every node with a channel)
is worth, given the sensors the bench has.

Two figures per place: how much of the plate's estimate variance (the Kalman observer's,
`benchlab.observer.batch.observe`, averaged over the runs) a sensor there removes, and how much it adds to the log
det of the information on the parameters designed for (`benchlab.design.fisher`) or, between two models, to the
test statistic that tells them apart (`discrimination.noncentrality`). A place the bench measures already is valued
the same way, by what losing its sensor would cost. The filter's covariance does not depend on the readings'
values, only on where they are, so a predicted run serves as well as a measured one: `benchlab design` ranks on the
designed run as predicted, diagnose on the diagnosed runs' inputs with every temperature the model's
(`rank_diagnosed_sensors`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from benchlab.design import fisher
from benchlab.identify.data import FitData, prepare
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.identify.fit import run_values, simulate_outputs
from benchlab.identify.spec import ModelSpec
from benchlab.network import ThermalNetwork

if TYPE_CHECKING:
    from benchlab.design.discrimination import DiscriminationDesign, Rival
    from protocols.limits import BenchLimits

#: The estimate the ranking is about: the pressure plate, which no sensor on the paper's bench reads.
PLATE = "T_pressure_plate"


@dataclass(frozen=True)
class SensorWorth:
    """One place: its channel and node, whether the bench measures it, and what a sensor there is worth."""

    channel: str
    node: str
    measured: bool
    plate_variance_reduction_pct: float  # share of the plate's mean estimate variance the sensor removes
    log_det_gain: float | None  # precision plans: information it adds on the designed-for parameters (log det)
    test_gain: float | None = None  # discrimination plans: what it adds to the test statistic between the rivals

    def line(self) -> str:
        now = "measured now" if self.measured else "no sensor now"
        second = (f"test statistic +{self.test_gain:.1f}" if self.test_gain is not None
                  else f"information +{self.log_det_gain:.2f} (log det)")
        return (f"  {self.channel} (node {self.node}, {now}): plate variance -{self.plate_variance_reduction_pct:.1f} %,"
                f" {second}")


#: A run as the observer is given it: the frame (inputs, and a reading of every place) and the values it is observed
#: with.
Observed = tuple[pd.DataFrame, Mapping[str, float]]


def _plate_variance(runs: Sequence[Observed], network: ThermalNetwork, sensors: Sequence[str]) -> float:
    """The plate's estimate variance with `sensors`, averaged over every sample of `runs`."""
    from benchlab.observer.batch import STD_SUFFIX, observe

    stds = [observe(run, params, list(sensors), network).estimate[PLATE + STD_SUFFIX].to_numpy()
            for run, params in runs]
    return float(sum(np.sum(std ** 2) for std in stds) / sum(len(std) for std in stds))


def plate_reductions(runs: Sequence[Observed], network: ThermalNetwork) -> dict[str, float]:
    """Each place's (channel's) share of the plate's mean estimate variance over `runs` that a sensor there removes,
    %: an unmeasured place by adding it to the bench's sensors, a measured one by what losing it would add; NaN for
    every place of a model without the plate."""
    if PLATE not in network.outputs:
        return {channel: np.nan for channel in network.outputs}
    sensors = list(network.measured)
    base = _plate_variance(runs, network, sensors)
    shares = {}
    for channel in network.outputs:
        measured = channel in sensors
        other = _plate_variance(runs, network, [s for s in sensors if s != channel] if measured
                                else [*sensors, channel])
        with_, without = (base, other) if measured else (other, base)
        shares[channel] = 100 * (1 - with_ / without)
    return shares


def _log_det(run: pd.DataFrame, params: Mapping[str, float], network: ThermalNetwork, sensors: Sequence[str],
             names: Sequence[str], interest: Sequence[str], prior: np.ndarray, noise: Mapping[str, float]) -> float:
    measured = replace(network, measured=tuple(sensors))
    data = prepare(run, FIT_STEP_S, name="design", network=measured)
    return fisher.log_det(prior + fisher.information(measured, params, names, [data], noise), names, interest)


def rank_sensors(run: pd.DataFrame, params: Mapping[str, float], network: ThermalNetwork, names: Sequence[str],
                 interest: Sequence[str], prior: np.ndarray, noise: Mapping[str, float]) -> list[SensorWorth]:
    """Every place of `network` with a channel, most plate variance removed first. `run`: the designed run as
    predicted (`fisher.predicted_run`); `noise`: the measured channels' noise, a new sensor taking the noisiest's."""
    sensors = list(network.measured)
    noise = {**{c: max(noise.values()) for c in network.outputs}, **noise}
    reductions = plate_reductions([(run, params)], network)
    base_det = _log_det(run, params, network, sensors, names, interest, prior, noise)
    ranked = []
    for channel, node in network.outputs.items():
        measured = channel in sensors
        other = [s for s in sensors if s != channel] if measured else [*sensors, channel]
        other_det = _log_det(run, params, network, other, names, interest, prior, noise)
        with_det, without_det = (base_det, other_det) if measured else (other_det, base_det)
        ranked.append(SensorWorth(channel, node, measured, reductions[channel], float(with_det - without_det)))
    return sorted(ranked, key=lambda s: (-np.nan_to_num(s.plate_variance_reduction_pct), -s.log_det_gain))


def discriminating_worths(network: ThermalNetwork, reductions: Mapping[str, float],
                          differences: Mapping[str, np.ndarray], noise: Mapping[str, float],
                          rho: float) -> list[SensorWorth]:
    """Every place of `network` that `differences` holds (the two models' outputs, first minus second, at
    diagnose's step), most plate variance removed first (`reductions`, `plate_reductions`): what its channel adds to
    the test statistic between the two (`noise`: the measured channels' misfit, a new sensor taking the worst;
    `rho`: the misfit's lag-1 autocorrelation)."""
    from benchlab.design.discrimination import noncentrality

    noise = {**{c: max(noise.values()) for c in network.outputs}, **noise}
    ranked = [SensorWorth(channel, node, channel in network.measured, reductions[channel], None,
                          noncentrality({channel: differences[channel]}, noise, rho))
              for channel, node in network.outputs.items() if channel in differences]
    return sorted(ranked, key=lambda s: (-np.nan_to_num(s.plate_variance_reduction_pct), -(s.test_gain or 0.0)))


def rank_discriminating_sensors(favoured: "Rival", other: "Rival", plan: "DiscriminationDesign", ambient_c: float,
                                limits: "BenchLimits") -> list[SensorWorth]:
    """Every place both rivals have a channel for, on the discrimination plan as predicted: the plate's variance a
    sensor there removes (the favoured model's observer) and the test statistic between the rivals it adds
    (`discriminating_worths`)."""
    from benchlab.design.discrimination import STEP_S, predicted_run_both

    run_a, run_b = predicted_run_both(favoured, other, plan.steps, ambient_c, limits)
    every = max(1, round(STEP_S / fisher.PREDICTION_DT_S))  # the statistic counts samples at diagnose's step
    diff = {c: (run_a[c].to_numpy() - run_b[c].to_numpy())[::every] for c in favoured.network.outputs
            if c in other.network.outputs}
    return discriminating_worths(favoured.network, plate_reductions([(run_a, favoured.params)], favoured.network),
                                 diff, plan.noise, min(favoured.rho, other.rho))


def rank_diagnosed_sensors(favoured: tuple[ModelSpec, Mapping[str, float]],
                           others: Sequence[tuple[ModelSpec, Mapping[str, float]]],
                           runs: Sequence[FitData]) -> list[list[SensorWorth]]:
    """For each of `others`, every place both it and `favoured` (each a model and its fit) have a channel for, on
    the diagnosed `runs` (at diagnose's step): the plate variance a sensor there removes, by the favoured model's
    observer on the runs' inputs with every temperature the favoured model's, and what its channel adds to the test
    statistic between the two over the runs (each measured channel's misfit the lower of the two models' on the
    runs, `discrimination.misfit`). The observer runs once per place for all of `others`."""
    from benchlab.design.discrimination import misfit

    network, params = favoured[0].network, {**favoured[0].fixed, **favoured[1]}
    simulated = [simulate_outputs(network, params, d, network.outputs) for d in runs]
    frames = []
    for data, outputs in zip(runs, simulated):
        frame = pd.DataFrame({**data.channels, **outputs})
        frame.attrs.update(dt=data.dt, source=data.name)
        frames.append((frame, run_values(params, data)))
    reductions = plate_reductions(frames, network)
    noise, rho = misfit(network, params, runs)
    ranked = []
    for spec, values in others:
        values = {**spec.fixed, **values}
        shared = [c for c in network.outputs if c in spec.network.outputs]
        theirs = [simulate_outputs(spec.network, values, d, shared) for d in runs]
        diff = {c: np.concatenate([ours[c] - other[c] for ours, other in zip(simulated, theirs)]) for c in shared}
        their_noise, their_rho = misfit(spec.network, values, runs)
        ranked.append(discriminating_worths(network, reductions, diff,
                                            {c: min(v, their_noise.get(c, np.inf)) for c, v in noise.items()},
                                            min(rho, their_rho)))
    return ranked
