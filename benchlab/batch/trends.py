"""Trends across a batch: each parameter (or figure) against run index or time, with its standard error.

The drift of R0, C_P or the heat split over a clutch's life shows as a slope: a straight line fitted to
the values weighted by their standard errors, its slope's standard error scaled up by the reduced
chi-square where the runs scatter more than their standard errors say (never down).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.batch.tasks import OK, SE_SUFFIX
from benchlab.report.plotting import new_figure, save

#: Per kind of batch, the columns whose trend matters, in this order, where the table has them.
SERIES = {"identify": ("R0", "C_P", "C_F", "C_A", "C_T", "R_AT", "R_Feng", "R_Tamb", "a1", "b1", "a2", "b2",
                       "rmse_K"),
          "wear": ("R0", "C_P", "split", "friction_energy_J", "wear_plate_um", "wear_flywheel_um", "health"),
          "diagnose": ("baseline_rmse_K", "best_rmse_K", "findings")}


@dataclass(frozen=True)
class Axis:
    """The trends' x value of each finished row (indexed like the table) and its label and unit."""

    x: pd.Series
    label: str
    unit: str


def axis(table: pd.DataFrame) -> Axis:
    """Days since the first run where every finished row has a creation time, else the run index."""
    ok = table[table["status"] == OK]
    created = pd.to_datetime(ok["created"], utc=True, errors="coerce") if "created" in ok else None
    if created is not None and len(ok) and created.notna().all():
        first = created.min()
        return Axis((created - first).dt.total_seconds() / 86400.0, f"days since {first:%Y-%m-%d %H:%M} UTC", "day")
    return Axis(ok["index"].astype(float), "run index", "run")


def points(table: pd.DataFrame, at: Axis, column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """x, value and standard error (None where the column has none) of the finished rows with finite numbers."""
    rows = table.loc[at.x.index]
    y = pd.to_numeric(rows[column], errors="coerce").to_numpy(float)
    keep = np.isfinite(y)
    se = None
    if column + SE_SUFFIX in rows:
        se = pd.to_numeric(rows[column + SE_SUFFIX], errors="coerce").to_numpy(float)
        keep &= np.isfinite(se) & (se > 0)
    return at.x.to_numpy(float)[keep], y[keep], None if se is None else se[keep]


def line_fit(x: np.ndarray, y: np.ndarray, se: np.ndarray | None) -> tuple[float, float, float]:
    """Slope, its standard error and intercept of y against x, weighted by 1/se² where standard errors are given.

    NaN where fewer than two distinct x; with two points and no standard errors the slope's error is NaN.
    """
    if len(x) < 2 or np.ptp(x) == 0:
        return np.nan, np.nan, np.nan
    weights = 1.0 / se if se is not None else np.ones_like(y)
    (slope, intercept), cov = np.polyfit(x, y, 1, w=weights, cov="unscaled")
    reduced_chi2 = np.sum((weights * (y - slope * x - intercept)) ** 2) / (len(x) - 2) if len(x) > 2 else np.nan
    if se is None:
        scale = reduced_chi2
    else:
        scale = 1.0 if not np.isfinite(reduced_chi2) else max(1.0, reduced_chi2)
    return float(slope), float(np.sqrt(cov[0, 0] * scale)), float(intercept)


def series(table: pd.DataFrame, kind: str) -> list[str]:
    """The columns to trend for this kind of batch that the table holds with at least one finite value."""
    at = axis(table)
    return [c for c in SERIES[kind] if c in table.columns and len(points(table, at, c)[0])]


def trend_table(table: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """Per column: points, first and last value, slope per axis unit with its standard error, and the change
    of the fitted line over the batch in % of its start."""
    at = axis(table)
    rows = []
    for column in columns:
        x, y, se = points(table, at, column)
        slope, slope_se, intercept = line_fit(x, y, se)
        start = intercept + slope * x.min() if len(x) else np.nan
        rows.append({"column": column, "points": len(y), "first": y[0] if len(y) else np.nan,
                     "last": y[-1] if len(y) else np.nan, "axis": at.label, f"slope_per_{at.unit}": slope,
                     f"slope_se_per_{at.unit}": slope_se, "slope_over_se": slope / slope_se,
                     "change_pct": 100.0 * slope * np.ptp(x) / abs(start) if len(x) and start else np.nan})
    return pd.DataFrame(rows)


def plot(table: pd.DataFrame, columns: Sequence[str], path: Path, title: str) -> Path:
    """One panel per column: values with standard-error bars against the trends' axis, and the fitted line."""
    at = axis(table)
    ncols = 2 if len(columns) > 1 else 1
    nrows = -(-len(columns) // ncols)
    fig = new_figure(5.0 * ncols, 2.2 * nrows + 0.6)
    fig.suptitle(title)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
    for ax, column in zip(axes.flat, columns):
        x, y, se = points(table, at, column)
        ax.errorbar(x, y, yerr=se, fmt="o", ms=3, capsize=2, color="tab:blue")
        slope, slope_se, intercept = line_fit(x, y, se)
        if np.isfinite(slope):
            ax.plot(x, intercept + slope * x, "-", color="tab:red", lw=1,
                    label=f"slope {slope:.3g} ± {slope_se:.2g} per {at.unit}")
            ax.legend(fontsize=7, loc="best")
        ax.set_ylabel(column)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(columns):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(at.label)
    return save(fig, path)
