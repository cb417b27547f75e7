"""Residual analysis of a system-identification toolbox: residual over time, its autocorrelation, and the
residual against engine speed and friction power, with the whiteness and input-correlation tests.

Residuals and tests are identify's own (benchlab.identify.residuals.run_residuals: the model from the run's
start as its early readings give it, simulated − measured at identification's step), so the page and `identify` agree.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.identify.residuals import autocorrelation, residual_start, run_residuals
from benchlab.identify.metrics import RESIDUAL_LABEL
from benchlab.model.params import ModelParams
from benchlab.network.simulation import simulate
from benchlab.report.plotting import colour, new_figure, run_name, save, symbol
from benchlab.report.scores import Estimate

#: Longest autocorrelation lag drawn: longer than a Table 1 cycle's cool-down (30-120 s).
ACF_LAG_S = 180.0
#: The clutch's two scatter panels (axis label, scale); another model shows its first two residual inputs.
PANELS = {"engine_speed": (r"engine speed $\omega_e$ (rpm)", 1.0), "friction_power": ("friction power P (kW)", 1e-3)}


@dataclass(frozen=True)
class Residuals:
    """Simulated − measured per predicted channel at the identification step, the inputs beside it, the tests."""

    label: str
    run: str
    step_s: float
    time_s: np.ndarray
    residual: dict[str, np.ndarray]
    inputs: dict[str, np.ndarray]
    tests: dict[str, dict]


def residuals(run: pd.DataFrame, est: Estimate, params: ModelParams) -> Residuals:
    """Residuals of `est`'s model (`params`) on `run` at the identification step, from identify's residual start
    (benchlab.identify.residuals.residual_start), with identify's residual tests on each channel."""
    r = run_residuals(run, simulate(run, params, initial=residual_start(run, params)), params)
    return Residuals(est.label, run_name(run), r.step_s, r.time_s, r.residual, r.inputs, r.tests)


def plot_residuals(res: Residuals, path: "str | os.PathLike[str]") -> Path:
    """Four panels: residual vs time, autocorrelation with the 99 % white-noise bound, vs engine speed, vs friction
    power (another model: vs its first two residual inputs)."""
    fig = new_figure(11, 8)
    (over_time, acf), (vs_first, vs_second) = fig.subplots(2, 2)
    max_lag = int(round(ACF_LAG_S / res.step_s))
    lags = np.arange(max_lag + 1) * res.step_s
    panels = [k for k in PANELS if k in res.inputs] if set(PANELS) <= set(res.inputs) else list(res.inputs)[:2]
    for i, (c, r) in enumerate(res.residual.items()):
        style = {"color": colour(c, i), "label": symbol(c)}
        over_time.plot(res.time_s / 60.0, r, lw=0.6, **style)
        acf.plot(lags, autocorrelation(r, max_lag), lw=1.0, **style)
        dots = {"s": 2, "alpha": 0.25, "rasterized": True, **style}
        for ax, name in zip((vs_first, vs_second), panels):
            ax.scatter(res.inputs[name] * PANELS.get(name, ("", 1.0))[1], r, **dots)
    bound = max(t["confidence_bound"] for t in res.tests.values())
    acf.axhspan(-bound, bound, color="0.85", label=r"$\pm 2.58/\sqrt{N}$ (99 %, white noise)")
    over_time.set(xlabel="time (min)", ylabel=f"{RESIDUAL_LABEL} (K)", title="residual over time")
    acf.set(xlabel="lag (s)", ylabel="autocorrelation (1)", title="whiteness: residual autocorrelation")
    for ax, name in zip((vs_first, vs_second), panels):
        ax.set(xlabel=PANELS.get(name, (name, 1.0))[0], ylabel=f"{RESIDUAL_LABEL} (K)", title=f"residual vs {name}")
    for ax in (over_time, acf, vs_first, vs_second):
        ax.axhline(0.0, color="k", lw=0.5)
        ax.legend(loc="best", fontsize=8, markerscale=4)
    fig.suptitle(f"Residual analysis – {res.run}, {res.label} model, at the identification step of "
                 f"{res.step_s:g} s")
    return save(fig, path)
