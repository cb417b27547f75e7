"""Residual analysis as a system-identification toolbox does it: whiteness and correlation with inputs.

One home for `identify` and `report`: `run_residuals` takes the model as `benchlab.simulate` runs it (every state
starts at the run's first measured values, contract §2), compares it with identification's targets at its step
and applies `residual_tests`. Residuals are simulated − measured (benchlab.metrics.residual).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from benchlab.identify.data import prepare
from benchlab.metrics import residual as model_error

if TYPE_CHECKING:
    from benchlab.model.definition import ModelDefinition
    from benchlab.params import ModelParams

#: Inputs the residuals are correlated with: the clutch's, where a run has them.
RESIDUAL_INPUTS = ("friction_power", "engine_speed", "clutch_state")


def residual_inputs(model: "ModelDefinition | None", channels: Sequence[str]) -> list[str]:
    """The signals residuals are correlated with: the clutch's operating point where the runs have it, then
    every channel the model's laws read."""
    read = sorted(model.law_channels()) if model is not None else []
    return [k for k in dict.fromkeys([*RESIDUAL_INPUTS, *read]) if k in channels]


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation at lags 0..max_lag (NaN skipped by zeroing after centring)."""
    x = np.where(np.isfinite(x), x - np.nanmean(x), 0.0)
    denom = float(np.dot(x, x))
    return np.array([np.dot(x[k:], x[: len(x) - k]) / denom if denom > 0 else 0.0 for k in range(max_lag + 1)])


def cross_correlation(residual: np.ndarray, signal: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised correlation of the residual with the signal at lags 0..max_lag (signal leading)."""
    r = np.where(np.isfinite(residual), residual - np.nanmean(residual), 0.0)
    s = np.where(np.isfinite(signal), signal - np.nanmean(signal), 0.0)
    denom = np.sqrt(np.dot(r, r) * np.dot(s, s))
    return np.array([np.dot(r[k:], s[: len(s) - k]) / denom if denom > 0 else 0.0 for k in range(max_lag + 1)])


def residual_tests(residual: np.ndarray, inputs: dict[str, np.ndarray], max_lag: int = 50,
                   lags: Sequence[int] = (1, 5, 20)) -> dict[str, object]:
    """Whiteness (share of autocorrelations outside ±2.58/√N) and the strongest input correlations."""
    n = int(np.sum(np.isfinite(residual)))
    bound = 2.58 / np.sqrt(max(n, 1))
    acf = autocorrelation(residual, max_lag)
    report: dict[str, object] = {
        "samples": n,
        "confidence_bound": bound,
        "autocorrelation": {int(k): float(acf[k]) for k in lags if k <= max_lag},
        "whiteness_outside_pct": float(100 * np.mean(np.abs(acf[1:]) > bound)),
        "white": bool(np.mean(np.abs(acf[1:]) > bound) <= 0.05),
        "input_correlation": {},
    }
    for name, signal in inputs.items():
        ccf = cross_correlation(residual, signal, max_lag)
        report["input_correlation"][name] = float(ccf[np.argmax(np.abs(ccf))])
    return report


@dataclass(frozen=True)
class RunResiduals:
    """A model's residuals on one run at identification's step, the inputs beside them, and their tests."""

    step_s: float
    time_s: np.ndarray
    residual: dict[str, np.ndarray]  # measured channel -> simulated − measured, K
    inputs: dict[str, np.ndarray]
    tests: dict[str, dict]


def run_residuals(run: pd.DataFrame, simulated: pd.DataFrame, params: "ModelParams | None" = None) -> RunResiduals:
    """Residuals of `simulated` (benchlab.simulate's output for `run` with `params`, default the clutch) against
    identification's targets (centred block means of the model's measured channels, benchlab.identify.data.prepare
    at its default step), with `residual_tests` on each measured channel."""
    data = prepare(run, network=params.network if params is not None else None)
    picks = slice(0, len(data) * data.block, data.block)
    residual = {c: model_error(simulated[c].to_numpy()[picks], target) for c, target in data.targets.items()}
    inputs = {k: data.channels[k] for k in residual_inputs(params.definition if params is not None else None,
                                                           list(data.channels))}
    return RunResiduals(data.dt, run["time"].to_numpy()[picks], residual, inputs,
                        {c: residual_tests(r, inputs) for c, r in residual.items()})
