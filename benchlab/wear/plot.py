"""The wear figure: energy, lining temperatures and wear over the run, and the remaining-life distribution."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after selecting the headless backend
import numpy as np  # noqa: E402

from benchlab.report.plotting import save  # noqa: E402
from benchlab.wear.analysis import WearReport  # noqa: E402


def plot_wear(report: WearReport, path: "str | os.PathLike[str]") -> None:
    """Write a four-panel PNG: power and cumulative energy, ϑ_P/ϑ_F, wear per side, life histogram."""
    minutes = report.time / 60.0
    fig, axes = plt.subplots(4, 1, figsize=(9, 11), constrained_layout=True)
    ax = axes[0]
    ax.plot(minutes, report.power_w / 1e3, lw=0.6, color="tab:gray", label="friction power")
    ax.set_ylabel("P (kW)")
    energy = ax.twinx()
    energy.plot(minutes, np.cumsum(report.power_w) * report.dt / 1e3, color="tab:red", label="cumulative energy")
    energy.set_ylabel("E (kJ)")
    lines = ax.get_lines() + energy.get_lines()  # one legend for both axes of the panel
    ax.legend(lines, [line.get_label() for line in lines], loc="upper left", fontsize=8)
    ax.set_title(f"{len(report.engagements)} engagements, {report.friction_energy_j / 1e3:.1f} kJ")
    ax = axes[1]
    ax.plot(minutes, report.temperatures["T_pressure_plate"], label=r"$\vartheta_P$ model (plate side)")
    ax.plot(minutes, report.temperatures["T_flywheel"], label=r"$\vartheta_F$ model (flywheel side)")
    ax.plot(minutes, report.measured_flywheel_c, lw=0.6, color="k", alpha=0.5, label=r"$\vartheta_F$ measured")
    ax.set_ylabel("temperature (°C)")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[2]
    for name, label in (("wear_plate_mm", "plate side"), ("wear_flywheel_mm", "flywheel side")):
        ax.plot(minutes, report.history.cumulative[name] * 1e3, label=label)
    ax.set_ylabel("lining wear per face (µm)")
    ax.set_xlabel("time (min)")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[3]
    life = report.life.engagements[np.isfinite(report.life.engagements)]
    if len(life):
        ax.hist(life, bins=40, color="tab:blue", alpha=0.7)
        for key, value in report.life.percentiles(report.life.engagements).items():
            if value is not None:
                ax.axvline(value, color="k", ls="--", lw=0.8)
                ax.annotate(key.upper(), (value, ax.get_ylim()[1] * 0.9), fontsize=8)
    else:
        ax.text(0.5, 0.5, "no failure within the searched horizon", ha="center", transform=ax.transAxes)
    ax.set_xlabel("remaining life (engagements)")
    ax.set_ylabel("Monte Carlo paths")
    try:
        save(fig, path)
    finally:
        plt.close(fig)
