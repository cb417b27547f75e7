"""Error figures of contract section 5: RMSE in K over the predicted channels, NRMSE per channel in %.

Also the one home of the residual's sign: every residual benchlab computes, tests, plots or reports is
simulated − measured (positive: the model is warmer than the measurement), see docs/report.md.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

import numpy as np
import pandas as pd

from benchlab.model.clutch import PREDICTED_CHANNELS

#: How a residual axis or table is labelled, everywhere: the sign convention of `residual`.
RESIDUAL_LABEL = "simulated − measured"
Values = TypeVar("Values", np.ndarray, pd.Series, float)


def residual(simulated: Values, measured: Values) -> Values:
    """The model's error: simulated − measured (K for temperatures); NaN where either is missing."""
    return simulated - measured


def rmse_k(measured: pd.DataFrame, simulated: pd.DataFrame, channels: Iterable[str] = PREDICTED_CHANNELS) -> float:
    """Root-mean-square error in K over all valid samples of the given channels together."""
    return _rms([_square_sum(measured, simulated, c) for c in channels])


def nrmse_pct(measured: pd.DataFrame, simulated: pd.DataFrame, channels: Iterable[str] = PREDICTED_CHANNELS) -> float:
    """100 * RMSE / (max - min of the measured signal), per channel, then averaged."""
    return _mean_finite(channel_nrmse_pct(measured, simulated, channels).values())


def channel_rmse_k(measured: pd.DataFrame, simulated: pd.DataFrame,
                   channels: Iterable[str] = PREDICTED_CHANNELS) -> dict[str, float]:
    """RMSE in K of each channel on its own."""
    return {c: rmse_k(measured, simulated, (c,)) for c in channels}


def channel_nrmse_pct(measured: pd.DataFrame, simulated: pd.DataFrame,
                      channels: Iterable[str] = PREDICTED_CHANNELS) -> dict[str, float]:
    """NRMSE in % of each channel on its own (NaN where the channel does not vary)."""
    return {c: _nrmse(rmse_k(measured, simulated, (c,)), measured, c) for c in channels}


def error_figures(measured: pd.DataFrame, simulated: pd.DataFrame, channels: Iterable[str]) -> dict:
    """rmse_k and nrmse_pct of the channels together and of each (contract section 5's figures, as `evaluate`
    reports them), each channel's error summed once."""
    sums = {c: _square_sum(measured, simulated, c) for c in channels}
    each = {c: {"rmse_K": _rms([s]), "nrmse_pct": _nrmse(_rms([s]), measured, c)} for c, s in sums.items()}
    return {"rmse_K": _rms(list(sums.values())), "nrmse_pct": _mean_finite(v["nrmse_pct"] for v in each.values()),
            "channels": each}


#: Samples per pass of `_square_sum`: its temporaries stay small whatever the run's length (a run-sized one is a fresh
#: mapping the kernel zero-fills page by page: half the CPU of a 24 h evaluation went there).
SUM_CHUNK = 1 << 16


def _square_sum(measured: pd.DataFrame, simulated: pd.DataFrame, channel: str) -> tuple[float, int]:
    """The sum of the channel's squared valid residuals and their count, a chunk of samples at a time."""
    sim, meas = simulated[channel], measured[channel]
    if not (sim.index is meas.index or sim.index.equals(meas.index)):
        sim, meas = sim.align(meas)  # as `residual` of the two series would
    sim, meas = sim.to_numpy(np.float64), meas.to_numpy(np.float64)
    total, count = 0.0, 0
    for start in range(0, len(sim), SUM_CHUNK):
        errors = residual(sim[start: start + SUM_CHUNK], meas[start: start + SUM_CHUNK])
        errors = errors[np.isfinite(errors)]
        total += float(np.einsum("i,i->", errors, errors))  # not np.dot: BLAS's threads would spin up for it
        count += errors.size
    return total, count


def _rms(sums: list[tuple[float, int]]) -> float:
    """The root mean square from (sum of squares, count) parts."""
    count = sum(n for _, n in sums)
    return float(np.sqrt(sum(total for total, _ in sums) / count)) if count else float("nan")


def _nrmse(rmse: float, measured: pd.DataFrame, channel: str) -> float:
    span = np.nanmax(measured[channel].to_numpy()) - np.nanmin(measured[channel].to_numpy())
    return 100.0 * rmse / span if span > 0 else float("nan")


def _mean_finite(values: Iterable[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


#: The median absolute deviation of normal noise times this is its standard deviation.
MAD_TO_SIGMA = 1.4826


def robust_sigma(values: np.ndarray) -> float:
    """The standard deviation of the noise in `values` (finite ones) from their median absolute deviation: outliers,
    kinks and steps barely move it."""
    return float(MAD_TO_SIGMA * np.median(np.abs(values - np.median(values))))


def difference_noise(values: np.ndarray) -> tuple[float, int]:
    """The white noise in a smooth measured signal, from its second differences (Gasser, Sroka & Jennen-Steinmetz
    1986): a temperature sampled at seconds barely curves between samples, so v[i-1] - 2 v[i] + v[i+1] is noise of
    variance 6 sigma^2 (robust_sigma keeps kinks and steps out). Returns (sigma, differences used)."""
    d2 = values[2:] - 2.0 * values[1:-1] + values[:-2]
    d2 = d2[np.isfinite(d2)]
    if d2.size < 10:
        return float("nan"), 0
    return robust_sigma(d2) / float(np.sqrt(6.0)), int(d2.size)
