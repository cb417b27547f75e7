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

import numpy as np
import pandas as pd

from benchlab.design import fisher
from benchlab.identify.data import prepare
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.network import ThermalNetwork

#: The estimate the ranking is about: the pressure plate, which no sensor on the paper's bench reads.
PLATE = "T_pressure_plate"


@dataclass(frozen=True)
class SensorWorth:
    """One place: its channel and node, whether the bench measures it, and what a sensor there is worth."""

    channel: str
    node: str
    measured: bool
    plate_variance_reduction_pct: float  # share of the plate's mean estimate variance the sensor removes
    log_det_gain: float  # information on the designed-for parameters it adds (natural log of the determinant)

    def line(self) -> str:
        now = "measured now" if self.measured else "no sensor now"
        return (f"  {self.channel} (node {self.node}, {now}): plate variance -{self.plate_variance_reduction_pct:.1f} %,"
                f" information +{self.log_det_gain:.2f} (log det)")


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
