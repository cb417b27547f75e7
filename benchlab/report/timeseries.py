"""Fig. 4 and Fig. 5 of the paper: measured against estimated temperatures over time."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import pandas as pd
from matplotlib.axes import Axes

from benchlab.clutch import PREDICTED_CHANNELS
from benchlab.metrics import RESIDUAL_LABEL
from benchlab.metrics import residual as model_error
from benchlab.report.plotting import (COLOURS, LABELS, MODEL_STYLES, SYMBOLS, minutes, new_figure, run_name, save,
                                      stride)
from benchlab.report.scores import Estimate


def _measured(ax: Axes, run: pd.DataFrame, channel: str, k: int) -> None:
    ax.plot(minutes(run)[::k], run[channel].to_numpy()[::k], color="k", lw=0.8, alpha=0.55, zorder=3,
            label=f"{SYMBOLS[channel]} measured")
    ax.set_ylabel(f"{SYMBOLS[channel]} (°C)")


def plot_fit(run: pd.DataFrame, est: Estimate, path: "str | os.PathLike[str]") -> Path:
    """Fig. 4: measured and estimated ϑ_F, ϑ_A, ϑ_T over the run, the residual (simulated − measured) underneath."""
    t, k, sim = minutes(run), stride(len(run)), est.simulated
    fig = new_figure(10, 10)
    axes = fig.subplots(4, 1, sharex=True, height_ratios=(2, 2, 2, 1.5))
    axes[0].plot(t[::k], sim["T_pressure_plate"].to_numpy()[::k], color=COLOURS["T_pressure_plate"], lw=0.8,
                 ls="--", label=f"{SYMBOLS['T_pressure_plate']} model (not measured)")
    for ax, c in zip(axes, PREDICTED_CHANNELS):
        _measured(ax, run, c, k)
        ax.plot(t[::k], sim[c].to_numpy()[::k], color=COLOURS[c], lw=1.1,
                label=f"{SYMBOLS[c]} {est.label} model: RMSE {est.scores.channel_rmse_k[c]:.2f} K "
                      f"({est.scores.channel_nrmse_pct[c]:.1f} %)")
        ax.set_title(LABELS[c], fontsize=9, loc="left")
        ax.legend(loc="best", fontsize=8)
    residual = axes[3]
    for c in PREDICTED_CHANNELS:
        residual.plot(t[::k], model_error(sim[c], run[c]).to_numpy()[::k], color=COLOURS[c], lw=0.7,
                      label=SYMBOLS[c])
    residual.axhline(0.0, color="k", lw=0.5)
    residual.set_ylabel(f"{RESIDUAL_LABEL} (K)")
    residual.set_xlabel("time (min)")
    residual.legend(loc="best", fontsize=8, ncols=3)
    fig.suptitle(f"Fig. 4 – measured and estimated clutch temperatures, {run_name(run)}, {est.label} model: "
                 f"RMSE {est.scores.rmse_k:.2f} K, NRMSE {est.scores.nrmse_pct:.1f} %")
    return save(fig, path)


#: What Fig. 5 plots, as the paper's does: the flywheel and the chamber air (ϑ_T is slow and in Fig. 4).
COMPARISON_CHANNELS = ("T_flywheel", "T_air")


def plot_comparison(run: pd.DataFrame, estimates: Sequence[Estimate], path: "str | os.PathLike[str]") -> Path:
    """Fig. 5: measured ϑ_F and ϑ_A against each model on a validation run (RMSE in the legend), operating point below."""
    t, k = minutes(run), stride(len(run))
    fig = new_figure(10, 8.5)
    axes = fig.subplots(3, 1, sharex=True, height_ratios=(2, 2, 1.2))
    for ax, c in zip(axes, COMPARISON_CHANNELS):
        _measured(ax, run, c, k)
        for est, (colour, style) in zip(estimates, MODEL_STYLES):
            ax.plot(t[::k], est.simulated[c].to_numpy()[::k], color=colour, ls=style, lw=1.1,
                    label=f"{est.label} model: RMSE {est.scores.channel_rmse_k[c]:.2f} K "
                          f"({est.scores.channel_nrmse_pct[c]:.1f} %)")
        ax.set_title(LABELS[c], fontsize=9, loc="left")
        ax.legend(loc="best", fontsize=8)
    speed = axes[2]
    speed.plot(t[::k], run["engine_speed"].to_numpy()[::k], color="k", lw=0.8, label=r"engine speed $\omega_e$")
    speed.fill_between(t[::k], 0, 1, where=run["clutch_state"].to_numpy()[::k] > 0.5, step="post", color="0.85",
                       transform=speed.get_xaxis_transform(), label="clutch closed (S = 1)")
    speed.set_ylabel(r"$\omega_e$ (rpm)")
    speed.set_xlabel("time (min)")
    speed.legend(loc="best", fontsize=8)
    overall = "; ".join(f"{e.label} RMSE {e.scores.rmse_k:.2f} K ({e.scores.nrmse_pct:.1f} %)" for e in estimates)
    shown = ", ".join(SYMBOLS[c] for c in COMPARISON_CHANNELS)
    fig.suptitle(f"Fig. 5 – {shown}: models compared on {run_name(run)}; RMSE over all measured temperatures: "
                 f"{overall}")
    return save(fig, path)
