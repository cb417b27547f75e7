"""Fig. 4 and Fig. 5 of the paper: measured against estimated temperatures over time."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes

from benchlab.identify.metrics import RESIDUAL_LABEL
from benchlab.identify.metrics import residual as model_error
from benchlab.report.plotting import MODEL_STYLES, colour, label, minutes, new_figure, run_name, save, stride, symbol
from benchlab.report.scores import Estimate

PLATE = "T_pressure_plate"  # the clutch's unmeasured plate, drawn on the first panel where a model simulates it
#: What Fig. 5 plots, as the paper's does: the flywheel and the chamber air (ϑ_T is slow and in Fig. 4); another
#: model shows its first two measured channels.
COMPARISON_CHANNELS = ("T_flywheel", "T_air")


def _measured(ax: Axes, run: pd.DataFrame, channel: str, k: int) -> None:
    ax.plot(minutes(run)[::k], run[channel].to_numpy()[::k], color="k", lw=0.8, alpha=0.55, zorder=3,
            label=f"{symbol(channel)} measured")
    ax.set_ylabel(f"{symbol(channel)} (°C)")


def plot_fit(run: pd.DataFrame, est: Estimate, path: "str | os.PathLike[str]") -> Path:
    """Fig. 4: measured and estimated temperatures (the clutch's ϑ_F, ϑ_A, ϑ_T) over the run, the residual
    (simulated − measured) underneath."""
    t, k, sim = minutes(run), stride(len(run)), est.simulated
    channels = est.channels
    fig = new_figure(10, 2.5 * len(channels) + 2.5)
    axes = fig.subplots(len(channels) + 1, 1, sharex=True, height_ratios=(2,) * len(channels) + (1.5,))
    if PLATE in sim.columns:
        axes[0].plot(t[::k], sim[PLATE].to_numpy()[::k], color=colour(PLATE, 0), lw=0.8,
                     ls="--", label=f"{symbol(PLATE)} model (not measured)")
    for i, (ax, c) in enumerate(zip(axes, channels)):
        _measured(ax, run, c, k)
        ax.plot(t[::k], sim[c].to_numpy()[::k], color=colour(c, i), lw=1.1,
                label=f"{symbol(c)} {est.label} model: RMSE {est.scores.channel_rmse_k[c]:.2f} K "
                      f"({est.scores.channel_nrmse_pct[c]:.1f} %)")
        ax.set_title(label(c), fontsize=9, loc="left")
        ax.legend(loc="best", fontsize=8)
    residual = axes[-1]
    for i, c in enumerate(channels):
        residual.plot(t[::k], model_error(sim[c], run[c]).to_numpy()[::k], color=colour(c, i), lw=0.7,
                      label=symbol(c))
    residual.axhline(0.0, color="k", lw=0.5)
    residual.set_ylabel(f"{RESIDUAL_LABEL} (K)")
    residual.set_xlabel("time (min)")
    residual.legend(loc="best", fontsize=8, ncols=3)
    fig.suptitle(f"Fig. 4 – measured and estimated temperatures, {run_name(run)}, {est.label} model: "
                 f"RMSE {est.scores.rmse_k:.2f} K, NRMSE {est.scores.nrmse_pct:.1f} %")
    return save(fig, path)


def plot_comparison(run: pd.DataFrame, estimates: Sequence[Estimate], path: "str | os.PathLike[str]") -> Path:
    """Fig. 5: measured ϑ_F and ϑ_A (another model: its first two channels) against each model on a validation run
    (RMSE in the legend), the clutch's operating point below where the run has it."""
    t, k = minutes(run), stride(len(run))
    measured = estimates[0].channels
    channels = list(COMPARISON_CHANNELS) if set(COMPARISON_CHANNELS) <= set(measured) else list(measured[:2])
    operating = "engine_speed" in run.columns and "clutch_state" in run.columns
    fig = new_figure(10, 8.5)
    axes = fig.subplots(len(channels) + operating, 1, sharex=True,
                        height_ratios=(2,) * len(channels) + ((1.2,) if operating else ()), squeeze=False)[:, 0]
    for ax, c in zip(axes, channels):
        _measured(ax, run, c, k)
        for est, (line_colour, style) in zip(estimates, MODEL_STYLES):
            ax.plot(t[::k], est.simulated[c].to_numpy()[::k], color=line_colour, ls=style, lw=1.1,
                    label=f"{est.label} model: RMSE {est.scores.channel_rmse_k[c]:.2f} K "
                          f"({est.scores.channel_nrmse_pct[c]:.1f} %)")
        ax.set_title(label(c), fontsize=9, loc="left")
        ax.legend(loc="best", fontsize=8)
    if operating:
        _operating_point(axes[-1], run, t, k)
    overall = "; ".join(f"{e.label} RMSE {e.scores.rmse_k:.2f} K ({e.scores.nrmse_pct:.1f} %)" for e in estimates)
    shown = ", ".join(symbol(c) for c in channels)
    fig.suptitle(f"Fig. 5 – {shown}: models compared on {run_name(run)}\nRMSE over all measured temperatures: "
                 f"{overall}", fontsize=10)  # two lines: one would be cut at the figure's edges
    return save(fig, path)


def _operating_point(speed: Axes, run: pd.DataFrame, t: np.ndarray, k: int) -> None:
    """The clutch's engine speed with the clamped spans shaded."""
    speed.plot(t[::k], run["engine_speed"].to_numpy()[::k], color="k", lw=0.8, label=r"engine speed $\omega_e$")
    speed.fill_between(t[::k], 0, 1, where=run["clutch_state"].to_numpy()[::k] > 0.5, step="post", color="0.85",
                       transform=speed.get_xaxis_transform(), label="clutch closed (S = 1)")
    speed.set_ylabel(r"$\omega_e$ (rpm)")
    speed.set_xlabel("time (min)")
    speed.legend(loc="best", fontsize=8)
