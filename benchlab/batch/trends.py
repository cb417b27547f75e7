"""Trends across a batch: each parameter (or figure) against run index or time, with its standard error.

The drift of R0, C_P or the heat split over a clutch's life shows as a slope: a straight line fitted to
the values weighted by their standard errors. Whether the slope is a drift is judged against the scatter of
the runs about the line (the weighted fit's own residual variance, Student's t with n − 2 degrees of
freedom), not against the runs' standard errors alone: runs of one unchanged clutch scatter by more than one
fit's standard error says (start temperatures, operating points, sensor draws), and a test on the standard
errors alone read that scatter as ageing. A column is flagged as drifting only at a batch-wide false-alarm
rate of FALSE_ALARM_RATE (Bonferroni over the columns tested); benchmarks/coverage_study.py measures the rate on
identical simulated clutches.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from matplotlib.ticker import MaxNLocator
from scipy import stats

from benchlab.batch.tasks import OK, SE_SUFFIX
from benchlab.report.plotting import new_figure, save

#: Probability that a batch of one unchanged clutch flags any column (two-sided, Bonferroni over the columns).
FALSE_ALARM_RATE = 0.01
#: Runs spanning less than this are placed by run index: "per day" for runs minutes apart means nothing.
MIN_DAYS_AXIS = 1.0

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
    """Days since the first run where every finished row has a creation time and they span at least
    MIN_DAYS_AXIS, else the run index."""
    ok = table[table["status"] == OK]
    created = pd.to_datetime(ok["created"], utc=True, errors="coerce") if "created" in ok else None
    if created is not None and len(ok) and created.notna().all():
        days = (created - created.min()).dt.total_seconds() / 86400.0
        if days.max() >= MIN_DAYS_AXIS:
            return Axis(days, f"days since {created.min():%Y-%m-%d %H:%M} UTC", "day")
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


@dataclass(frozen=True)
class SlopeTest:
    """A weighted line's slope, its standard error from the runs' scatter, intercept, degrees of freedom and the
    two-sided p-value of "no drift"."""

    slope: float
    slope_se: float
    intercept: float
    dof: int
    p_value: float


def line_fit(x: np.ndarray, y: np.ndarray, se: np.ndarray | None) -> SlopeTest:
    """Slope of y against x weighted by 1/se² (equal weights without standard errors), tested against the
    scatter about the line: the slope's error is scaled by the reduced chi-square (up or down), t with n − 2 dof.

    NaN where fewer than three points or fewer than two distinct x.
    """
    if len(x) < 3 or np.ptp(x) == 0:
        return SlopeTest(np.nan, np.nan, np.nan, max(len(x) - 2, 0), np.nan)
    weights = 1.0 / se if se is not None else np.ones_like(y)
    (slope, intercept), cov = np.polyfit(x, y, 1, w=weights, cov="unscaled")
    dof = len(x) - 2
    reduced_chi2 = np.sum((weights * (y - slope * x - intercept)) ** 2) / dof
    slope_se = float(np.sqrt(cov[0, 0] * reduced_chi2))
    p = float(2 * stats.t.sf(abs(slope) / slope_se, dof)) if slope_se > 0 else np.nan
    return SlopeTest(float(slope), slope_se, float(intercept), dof, p)


def drifting(p_values: Sequence[float], rate: float = FALSE_ALARM_RATE) -> list[bool]:
    """Which columns drift at a batch-wide false-alarm `rate`: p below rate / (columns tested) (Bonferroni)."""
    tested = sum(1 for p in p_values if np.isfinite(p))
    return [bool(np.isfinite(p) and p < rate / tested) for p in p_values]


def series(table: pd.DataFrame, kind: str) -> list[str]:
    """The columns to trend for this kind of batch that the table holds with at least one finite value."""
    at = axis(table)
    return [c for c in SERIES[kind] if c in table.columns and len(points(table, at, c)[0])]


def trend_table(table: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """Per column: points, first and last value, slope per axis unit with its standard error (runs' scatter),
    the change of the fitted line over the batch in % of its start, the p-value of "no drift" and whether the
    column is flagged as drifting (`drifting`)."""
    at = axis(table)
    rows = []
    for column in columns:
        x, y, se = points(table, at, column)
        fit = line_fit(x, y, se)
        start = fit.intercept + fit.slope * x.min() if len(x) else np.nan
        rows.append({"column": column, "points": len(y), "first": y[0] if len(y) else np.nan,
                     "last": y[-1] if len(y) else np.nan, "axis": at.label, f"slope_per_{at.unit}": fit.slope,
                     f"slope_se_per_{at.unit}": fit.slope_se, "slope_over_se": fit.slope / fit.slope_se,
                     "change_pct": 100.0 * fit.slope * np.ptp(x) / abs(start) if len(x) and start else np.nan,
                     "p_value": fit.p_value})
    out = pd.DataFrame(rows)
    out["drifting"] = drifting(out["p_value"].tolist()) if len(out) else []
    out["false_alarm_rate"] = FALSE_ALARM_RATE
    return out


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
        fit = line_fit(x, y, se)
        if np.isfinite(fit.slope):
            ax.plot(x, fit.intercept + fit.slope * x, "-", color="tab:red", lw=1,
                    label=f"slope {fit.slope:.3g} ± {fit.slope_se:.2g} per {at.unit}, p = {fit.p_value:.2g}")
            ax.legend(fontsize=7, loc="best")
        ax.set_ylabel(column)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(columns):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(at.label)
        if at.unit == "run":
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    return save(fig, path)
