"""Standard errors, correlations and identifiability warnings from the fit's Jacobian.

Residuals of a thermal fit are autocorrelated (slow model error, held sensor readings), so the
plain (JᵀJ)⁻¹s² understates the spread; the variance is inflated by the effective number of
independent residuals, estimated from their lag-1 autocorrelation (AR(1) approximation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchlab.identify.fit import FitResult

CORRELATION_LIMIT = 0.95
RELATIVE_SE_LIMIT = 0.5


@dataclass(frozen=True)
class Uncertainty:
    """Standard errors (physical units), correlation matrix, and plain-language warnings."""

    names: list[str]
    standard_errors: dict[str, float]
    correlation: np.ndarray
    inflation: float
    warnings: list[str]


def lag1_autocorrelation(residuals: np.ndarray) -> float:
    r = residuals - residuals.mean()
    denom = float(np.dot(r, r))
    return float(np.dot(r[1:], r[:-1]) / denom) if denom > 0 else 0.0


def estimate_uncertainty(result: FitResult) -> Uncertainty:
    """Covariance from the Jacobian, corrected for residual autocorrelation; flag what the data cannot tell."""
    J, r = result.jacobian, result.residuals
    n, p = J.shape
    rho = min(max(lag1_autocorrelation(r), 0.0), 0.999)
    inflation = (1 + rho) / (1 - rho)
    sigma2 = float(np.dot(r, r)) / max(n - p, 1)
    JtJ = J.T @ J
    cov = np.linalg.pinv(JtJ) * sigma2 * inflation
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    names = result.free_names
    warnings = []
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > CORRELATION_LIMIT:
                warnings.append(f"{names[i]} and {names[j]} are hard to tell apart (correlation {corr[i, j]:+.3f})")
    column_norm = np.sqrt(np.diag(JtJ)) * np.abs([result.params[k] for k in names])
    for i, name in enumerate(names):
        value = abs(result.params[name])
        if value > 0 and se[i] / value > RELATIVE_SE_LIMIT:
            warnings.append(f"{name} is poorly excited by the data (standard error {100 * se[i] / value:.0f} %)")
        elif column_norm[i] < 1e-6 * np.max(column_norm):
            warnings.append(f"{name} has no visible effect on the measured channels")
    if "C_P" in names:
        i = names.index("C_P")
        warnings.append(f"C_P is seen only through the flywheel and air temperatures (the pressure plate is not "
                        f"measured): its standard error is {100 * se[i] / result.params['C_P']:.1f} % and ϑ_P is "
                        f"an estimate, not a measurement")
    return Uncertainty(names, dict(zip(names, map(float, se))), corr, inflation, warnings)
