"""Residual analysis as a system-identification toolbox does it: whiteness and correlation with inputs."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


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
