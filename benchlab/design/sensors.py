"""Sensors as a design choice: what a temperature sensor at each place of the model (every node with a channel)
is worth, given the sensors the bench has.

Two figures per place, both on the designed run as predicted: how much of the plate's estimate variance
(the Kalman observer's, `benchlab.observer.batch.observe`, averaged over the run) a sensor there removes, and how
much it adds to the log det of the information on the parameters designed for (`benchlab.design.fisher`). A place
the bench measures already is valued the same way, by what losing its sensor would cost. The filter's covariance
does not depend on the readings' values, only on where they are, so the predicted run serves as well as a
measured one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from benchlab.design import fisher
from benchlab.identify.data import prepare
from benchlab.identify.defaults import FIT_STEP_S
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


def _plate_variance(run: pd.DataFrame, params: Mapping[str, float], network: ThermalNetwork,
                    sensors: Sequence[str]) -> float:
    from benchlab.observer.batch import STD_SUFFIX, observe

    std = observe(run, params, list(sensors), network).estimate[PLATE + STD_SUFFIX].to_numpy()
    return float(np.mean(std ** 2))


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
    plate = PLATE in network.outputs
    base_var = _plate_variance(run, params, network, sensors) if plate else np.nan
    base_det = _log_det(run, params, network, sensors, names, interest, prior, noise)
    ranked = []
    for channel, node in network.outputs.items():
        measured = channel in sensors
        other = [s for s in sensors if s != channel] if measured else [*sensors, channel]
        other_var = _plate_variance(run, params, network, other) if plate else np.nan
        other_det = _log_det(run, params, network, other, names, interest, prior, noise)
        with_var, without_var = (base_var, other_var) if measured else (other_var, base_var)
        with_det, without_det = (base_det, other_det) if measured else (other_det, base_det)
        ranked.append(SensorWorth(channel, node, measured, 100 * (1 - with_var / without_var),
                                  float(with_det - without_det)))
    return sorted(ranked, key=lambda s: (-np.nan_to_num(s.plate_variance_reduction_pct), -s.log_det_gain))


def rank_discriminating_sensors(favoured: "Rival", other: "Rival", plan: "DiscriminationDesign", ambient_c: float,
                                limits: "BenchLimits") -> list[SensorWorth]:
    """Every place both rivals have a channel for, on the discrimination plan as predicted: the plate's variance a
    sensor there removes (the favoured model's observer) and the test statistic between the rivals it adds (its
    channel's difference over its misfit; a new sensor taking the worst measured misfit). A measured place is
    valued by what losing it would cost."""
    from benchlab.design.discrimination import STEP_S, noncentrality, predicted_run_both

    run_a, run_b = predicted_run_both(favoured, other, plan.steps, ambient_c, limits)
    network, params = favoured.network, favoured.params
    sensors = list(network.measured)
    noise = {**{c: max(plan.noise.values()) for c in network.outputs}, **plan.noise}
    rho = min(favoured.rho, other.rho)
    every = max(1, round(STEP_S / fisher.PREDICTION_DT_S))  # the statistic counts samples at diagnose's step
    plate = PLATE in network.outputs
    base_var = _plate_variance(run_a, params, network, sensors) if plate else np.nan
    ranked = []
    for channel, node in network.outputs.items():
        if channel not in other.network.outputs:
            continue
        measured = channel in sensors
        other_var = _plate_variance(run_a, params, network,
                                    [s for s in sensors if s != channel] if measured else [*sensors, channel])
        with_var, without_var = (base_var, other_var) if measured else (other_var, base_var)
        diff = {channel: (run_a[channel].to_numpy() - run_b[channel].to_numpy())[::every]}
        ranked.append(SensorWorth(channel, node, measured, 100 * (1 - with_var / without_var) if plate else np.nan,
                                  None, noncentrality(diff, noise, rho)))
    return sorted(ranked, key=lambda s: (-np.nan_to_num(s.plate_variance_reduction_pct), -(s.test_gain or 0.0)))
