"""The observer's figure, after the paper's Fig. 4: each temperature estimated with its ±2σ band, the measurement
(marked where it is an observer input) and, on the simulated bench, the truth."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.observer.batch import STD_SUFFIX, Observation
from benchlab.report.plotting import COLOURS, LABELS, minutes, new_figure, run_name, save, stride


def plot_observation(run: pd.DataFrame, observation: Observation, truth: pd.DataFrame | None,
                     path: "str | os.PathLike[str]") -> Path:
    """One panel per state (the unmeasured ones first), one more per corrected law; minutes on the time axis."""
    t, k = minutes(run), stride(len(run))
    est, model = observation.estimate, observation.model
    names = [model.names[s] for s in model.states]
    names.sort(key=lambda name: name in run.columns)  # the states no sensor of the run reads first: the plate
    panels = names + model.adapted
    fig = new_figure(10, 2.3 * len(panels) + 1.0)
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))
    for ax, name in zip(axes, panels):
        colour = COLOURS.get(name, "tab:purple")
        value, spread = est[name].to_numpy()[::k], est[name + STD_SUFFIX].to_numpy()[::k]
        ax.fill_between(t[::k], value - 2 * spread, value + 2 * spread, color=colour, alpha=0.25, lw=0,
                        label="±2σ band")
        ax.plot(t[::k], value, color=colour, lw=1.1, label="estimate")
        if name in run.columns:
            used = name in model.sensors
            ax.plot(t[::k], run[name].to_numpy()[::k], color="k", lw=0.8 if used else 0.6,
                    alpha=0.55 if used else 0.35, ls="-" if used else ":",
                    label="measured, observer input" if used else "measured, not used")
        if truth is not None and name in truth.columns:
            error = est[name].to_numpy() - truth[name].to_numpy()
            covered = np.mean(np.abs(error) <= 2 * est[name + STD_SUFFIX].to_numpy())
            ax.plot(t[::k], truth[name].to_numpy()[::k], color="k", lw=1.0, ls="--",
                    label=f"truth (simulated bench): RMS error {np.sqrt(np.mean(error ** 2)):.2f} K, "
                          f"band covers {100 * covered:.0f} %")
        unit = "K/W" if name in model.adapted else "°C"
        ax.set_ylabel(f"{name} ({unit})" if name not in LABELS else f"{LABELS[name].split(' ', 1)[0]} ({unit})")
        ax.set_title(LABELS.get(name, f"{name}: resistance correction of the law, online"), fontsize=9, loc="left")
        ax.legend(loc="best", fontsize=7)
    axes[-1].set_xlabel("time (min)")
    sensors = ", ".join(model.sensors) or "none (open loop)"
    fig.suptitle(f"Fig. 4 with an observer – {run_name(run)}: estimated temperatures ±2σ, sensors: {sensors}")
    return save(fig, path)
