"""The diagnosis's figures (PNG, Agg): error by regime, the worst 10-minute window, the residual evidence,
each finding's binned residuals before and after, and the gains. All from held-out predictions."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchlab.diagnose.engine import ALPHA, Diagnosis, HeldOut
from benchlab.diagnose.evidence import FORMS, binned_means, residual_forms, run_signal, signal_unit
from benchlab.identify.metrics import RESIDUAL_LABEL
from benchlab.report.plotting import colour, label, new_figure, save, symbol
from benchlab.units import display

WINDOW_S = 600.0
WINDOW_STEP_S = 60.0
CLUTCH_INPUTS = (("engine_speed", "tab:purple"), ("clutch_speed", "tab:olive"))  # the window's input panel
BASELINE, FINAL = ("baseline", "tab:red"), ("final", "tab:blue")
CONFIDENCE_Z = 1.96  # error bars: 95 % intervals from the block-robust standard error
EVIDENCE_ROWS = 15


def plot_regimes(regimes: dict[str, dict], path: "str | os.PathLike[str]") -> Path:
    """Held-out RMSE per regime (columns: regime groups, rows: measured channels), baseline against final model."""
    groups = [g for g in regimes["baseline"] if g != "all"] or ["all"]
    channels = measured_channels(regimes)
    fig = new_figure(max(4.0, 3.0 * len(groups)), 2.3 * len(channels))
    axes = fig.subplots(len(channels), len(groups), squeeze=False)
    for row, channel in enumerate(channels):
        for col, group in enumerate(groups):
            ax = axes[row][col]
            labels = list(regimes["baseline"][group])
            x = np.arange(len(labels))
            for offset, (model, bar_colour), key in ((-0.2, BASELINE, "baseline"), (0.2, FINAL, "best")):
                values = [regimes[key][group][lab]["channels"][channel]["rmse_K"] for lab in labels]
                ax.bar(x + offset, [v if v is not None else 0.0 for v in values], 0.4, color=bar_colour, label=model)
            ax.set_xticks(x, labels, fontsize=7)
            ax.tick_params(axis="y", labelsize=7)
            if col == 0:
                ax.set_ylabel(f"{symbol(channel)} RMSE (K)")
            if row == 0:
                ax.set_title(group, fontsize=9)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Held-out RMSE by regime: baseline and final model")
    return save(fig, path)


def measured_channels(regimes: dict[str, dict]) -> list[str]:
    """The measured channels of a diagnosis's regime table (regime_errors)."""
    return list(regimes["baseline"]["all"]["all"]["channels"])


def worst_window(held: HeldOut, window_s: float = WINDOW_S) -> tuple[int, int, int]:
    """(run, first sample, end sample) of the window_s stretch where the held-out mean squared error over all
    measured channels is largest, windows starting every WINDOW_STEP_S."""
    best = (-1.0, 0, 0, 0)
    for i, (d, res) in enumerate(zip(held.datasets, held.residuals())):
        n, length, step = len(d), max(1, int(window_s / d.dt)), max(1, int(WINDOW_STEP_S / d.dt))
        squared = np.column_stack([r ** 2 for r in res.values()])
        for start in range(0, max(1, n - length + 1), step):
            part = squared[start:start + length]
            if np.isfinite(part).any():
                score = float(np.nanmean(part))
                if score > best[0]:
                    best = (score, i, start, min(n, start + length))
    return best[1], best[2], best[3]


def plot_window(result: Diagnosis, run_names: Sequence[str], path: "str | os.PathLike[str]") -> Path:
    """Measured against the baseline's and the final model's held-out predictions over the worst window, inputs below."""
    run, start, stop = worst_window(result.baseline_held)
    d = result.baseline_held.datasets[run]
    channels = list(d.targets)
    minutes = np.arange(start, stop) * d.dt / 60.0
    fig = new_figure(9.0, 2.2 * len(channels) + 4.4)
    axes = fig.subplots(len(channels) + 2, 1, sharex=True)
    for ax, channel in zip(axes, channels):
        ax.plot(minutes, d.targets[channel][start:stop], ".", ms=2, color="black", label="measured")
        for (model, line_colour), held in ((BASELINE, result.baseline_held), (FINAL, result.final_held)):
            ax.plot(minutes, held.predictions[run][channel][start:stop], color=line_colour, lw=1.2,
                    ls="--" if model == "baseline" else "-", label=f"{model} (held-out)")
        ax.set_ylabel(f"{symbol(channel)} (°C)")
        ax.set_title(label(channel), fontsize=9)
    axes[0].legend(fontsize=8)
    errors = axes[len(channels)]
    errors.axhline(0.0, color="black", lw=0.6)
    for (model, _), held in ((BASELINE, result.baseline_held), (FINAL, result.final_held)):
        for i, (channel, r) in enumerate(held.residuals()[run].items()):
            errors.plot(minutes, r[start:stop], color=colour(channel, i), lw=1.0,
                        ls="--" if model == "baseline" else "-", label=f"{symbol(channel)} {model}")
    errors.set_ylabel(f"{RESIDUAL_LABEL} (K)")
    errors.set_title("held-out residuals (dashed: baseline, solid: final)", fontsize=9)
    errors.legend(fontsize=7, ncol=2)
    _inputs(axes[-1], d, start, stop, minutes)
    axes[-1].set_xlabel(f"time in run {run_names[run]} (min)")
    fig.suptitle(f"Worst {WINDOW_S / 60:.0f} minutes of the baseline: measured and held-out predictions")
    return save(fig, path)


def _inputs(speeds, d, start: int, stop: int, minutes: np.ndarray) -> None:
    """The window's inputs: the clutch's speeds and friction power, another model's first two non-temperature channels."""
    if all(name in d.channels for name, _ in CLUTCH_INPUTS) and "friction_power" in d.channels:
        for name, line in CLUTCH_INPUTS:
            speeds.plot(minutes, d.channels[name][start:stop], color=line, label=name)
        speeds.set_ylabel("speed (rpm)")
        power = speeds.twinx()
        power.fill_between(minutes, d.channels["friction_power"][start:stop] / 1000.0, color="tab:orange",
                           alpha=0.3, label="friction power")
        power.set_ylabel("friction power (kW)")
    else:
        shown = [c for c in d.channels if c != "time" and d.units.get(c) != "degC"][:2]
        for i, (ax, name) in enumerate(zip((speeds, speeds.twinx()), shown)):
            ax.plot(minutes, d.channels[name][start:stop], color=f"C{i + 4}", label=name)
            ax.set_ylabel(f"{name} ({display(d.units.get(name, '1'))})")
    speeds.legend(fontsize=8, loc="upper left")


def plot_evidence(rows: Sequence[dict], path: "str | os.PathLike[str]", count: int = EVIDENCE_ROWS) -> Path:
    """The top of the evidence table: share explained by the signal against the share circular shifts give."""
    top = list(rows[:count])[::-1]
    fig = new_figure(8.0, 0.35 * len(top) + 1.5)
    ax = fig.subplots()
    y = np.arange(len(top))
    colours = ["tab:red" if r["p_value"] < ALPHA else "tab:gray" for r in top]
    ax.barh(y, [r["explained_pct"] for r in top], color=colours)
    ax.plot([r["shifted_pct"] for r in top], y, "k|", ms=12, label="median over circular shifts")
    ax.set_yticks(y, [f"{r['signal']} → {r['channel']} {r['form']}  (p = {r['p_value']:.3f})" for r in top],
                  fontsize=8)
    ax.set_xlabel("residual variance explained by binned means (%)")
    ax.set_xlim(0, 100)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Residual evidence, baseline model (red: p < {ALPHA:g})")
    return save(fig, path)


def plot_binned(before: HeldOut, after: HeldOut, signal: str, path: "str | os.PathLike[str]", title: str) -> Path:
    """Binned mean residual (level and rate) against the signal, before and after, with 95 % block-robust intervals."""
    datasets = before.datasets
    channels = list(datasets[0].targets)
    values = [run_signal(signal, d.channels, d.dt) for d in datasets]
    forms = [(model, line_colour, residual_forms(held)) for model, line_colour, held
             in (("before (without it)", BASELINE[1], before), ("after (with it)", FINAL[1], after))]
    fig = new_figure(12.0, 6.5)
    axes = fig.subplots(len(FORMS), len(channels), squeeze=False)
    for row, (form, unit) in enumerate(FORMS.items()):
        for col, channel in enumerate(channels):
            ax = axes[row][col]
            ax.axhline(0.0, color="black", lw=0.6)
            for model, line_colour, residuals in forms:
                b = binned_means(values, [r[channel] for r in residuals[form]], datasets[0].dt)
                ax.errorbar(b.centre, b.mean, CONFIDENCE_Z * b.stderr, fmt="o-", ms=3, capsize=2, color=line_colour,
                            label=model)
            ax.set_xlabel(f"{signal} ({display(signal_unit(signal, datasets[0].units))})")
            ax.set_ylabel(f"{symbol(channel)} residual {form} ({unit})")
            ax.set_title(f"{label(channel)}: {form}", fontsize=9, color=colour(channel, col))
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title)
    return save(fig, path)


def plot_gains(regimes: dict[str, dict], findings: Sequence[dict], path: "str | os.PathLike[str]") -> Path:
    """Held-out RMSE per channel, baseline against final, and each finding's RMSE before and after it."""
    fig = new_figure(11.0, 3.8)
    left, right = fig.subplots(1, 2, width_ratios=(1, max(1, len(findings))))
    channels = measured_channels(regimes)
    x = np.arange(len(channels))
    for offset, (model, bar_colour), key in ((-0.2, BASELINE, "baseline"), (0.2, FINAL, "best")):
        rmse = [regimes[key]["all"]["all"]["channels"][c]["rmse_K"] or 0.0 for c in channels]
        left.bar(x + offset, rmse, 0.4, color=bar_colour, label=model)
    left.set_xticks(x, [symbol(c) for c in channels])
    left.set_ylabel("held-out RMSE (K)")
    left.set_title("per channel", fontsize=9)
    left.legend(fontsize=8)
    if findings:
        x = np.arange(len(findings))
        right.bar(x - 0.2, [f["rmse_before_K"] for f in findings], 0.4, color=BASELINE[1], label="without it")
        right.bar(x + 0.2, [f["rmse_after_K"] for f in findings], 0.4, color=FINAL[1], label="with it")
        for i, f in enumerate(findings):
            right.annotate(f"−{f['gain_pct']:.0f} %", (i + 0.2, f["rmse_after_K"]), ha="center", va="bottom", fontsize=8)
        right.set_xticks(x, [f["candidate"] for f in findings], fontsize=8)
        right.legend(fontsize=8)
    else:
        right.text(0.5, 0.5, "no finding: no extension lowers the held-out error significantly",
                   ha="center", va="center", transform=right.transAxes)
    right.set_ylabel("held-out RMSE, all channels (K)")
    right.set_title("per finding", fontsize=9)
    fig.suptitle("How much better: held-out RMSE")
    return save(fig, path)
