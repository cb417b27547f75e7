"""Innovation consistency of the observer (NIS): does the filter's spread hold what its sensors read?

A filter whose model and noise are right sees each fresh reading y fall about its prediction ẑ with the variance
it states, P + R: the normalised innovation squared (y − ẑ)² / (P + R) averages 1. A wrong model (a linear
parameter file on a nonlinear clutch, a law `--adapt` cannot follow) shows as innovations far beyond that spread,
and then the ±2σ band of the states nobody measures (the pressure plate) cannot be trusted either. The prediction
is the estimate one grid step (10 ms) before the reading, its spread that step's; a step moves the temperatures
by far less than a reading's noise. Per sensor the NIS is averaged over WINDOW_S windows and each window mean
tested against its χ² bound (readings × window mean ~ χ²(readings)) at level ALPHA; a sensor is consistent when
at most MAX_OUTSIDE_SHARE of its windows lie outside, ALPHA's share plus room for the slow sensor errors.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

WINDOW_S = 60.0
ALPHA = 0.01
MAX_OUTSIDE_SHARE = 0.10


@dataclass(frozen=True)
class Consistency:
    """One sensor's innovation consistency: readings used, mean NIS (1 when consistent), windows and the share of
    them beyond the χ² bound."""

    sensor: str
    readings: int
    mean_nis: float
    windows: int
    outside_pct: float

    @property
    def consistent(self) -> bool:
        return self.windows > 0 and self.outside_pct <= 100 * MAX_OUTSIDE_SHARE

    def as_dict(self) -> dict[str, object]:
        return {"sensor": self.sensor, "readings": self.readings, "mean_nis": self.mean_nis,
                "windows": self.windows, "outside_pct": self.outside_pct, "consistent": self.consistent,
                "window_s": WINDOW_S, "alpha": ALPHA}


def innovations(readings: np.ndarray, estimate: np.ndarray, spread: np.ndarray, sensor_var: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Each fresh reading's innovation against the estimate one step before, and its stated variance P + R (NaN
    where there is no reading)."""
    innovation, variance = np.full(len(readings), np.nan), np.full(len(readings), np.nan)
    innovation[1:] = readings[1:] - estimate[:-1]
    variance[1:] = np.where(np.isfinite(innovation[1:]), spread[:-1] ** 2 + sensor_var, np.nan)
    return innovation, variance


def window_test(innovation: np.ndarray, variance: np.ndarray, window: int) -> tuple[int, float]:
    """Windows with readings, and the % of them whose innovations exceed the stated spread: summed NIS above
    χ²(readings)'s 1 − ALPHA quantile, or their mean beyond ALPHA's normal bound (a bias white noise would not
    hold for a window: what a wrong model leaves while `--adapt` keeps each innovation small)."""
    n = len(innovation) // window
    e, v = innovation[: n * window].reshape(n, window), variance[: n * window].reshape(n, window)
    count = np.sum(np.isfinite(e), axis=1)
    used = count > 0
    total = np.nansum(e ** 2 / v, axis=1)[used]
    bias = np.abs(np.nansum(e, axis=1)[used]) / np.sqrt(np.nansum(v, axis=1)[used])
    outside = (total > stats.chi2.ppf(1 - ALPHA, count[used])) | (bias > stats.norm.ppf(1 - ALPHA / 2))
    return int(used.sum()), float(100 * np.mean(outside)) if used.any() else np.nan


def innovation_consistency(sensors: Sequence[str], readings: np.ndarray, estimate: np.ndarray, spread: np.ndarray,
                           sensor_var: np.ndarray, dt: float) -> list[Consistency]:
    """Per sensor (columns of `readings`, fresh readings with NaN between; `estimate`/`spread` of its state)."""
    window = max(1, int(round(WINDOW_S / dt)))
    out = []
    for j, sensor in enumerate(sensors):
        e, v = innovations(readings[:, j], estimate[:, j], spread[:, j], float(sensor_var[j]))
        used = np.isfinite(e)
        windows, outside = window_test(e, v, window)
        out.append(Consistency(sensor, int(used.sum()), float(np.mean(e[used] ** 2 / v[used])) if used.any()
                               else np.nan, windows, outside))
    return out
