"""Plotting ground shared by the report's figures: a headless Agg canvas, channel names, time axis, saving.

Figures are drawn on `matplotlib.figure.Figure` with an Agg canvas attached here, never through pyplot,
so no display is needed and no global backend state changes in the caller's process.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from benchlab.outputs import replacing

#: At most this many points per plotted line: beyond it a line only costs rendering time.
MAX_POINTS = 20_000
DPI = 110
LABELS = {"T_pressure_plate": r"$\vartheta_P$ pressure plate", "T_flywheel": r"$\vartheta_F$ flywheel",
          "T_air": r"$\vartheta_A$ chamber air", "T_housing": r"$\vartheta_T$ transmission housing"}
SYMBOLS = {"T_pressure_plate": r"$\vartheta_P$", "T_flywheel": r"$\vartheta_F$", "T_air": r"$\vartheta_A$",
           "T_housing": r"$\vartheta_T$"}
#: (colour, line style) of the report's first model (--params) and second model (--compare).
MODEL_STYLES = (("tab:red", "-"), ("tab:blue", "--"))
COLOURS = {"T_pressure_plate": "tab:orange", "T_flywheel": "tab:red", "T_air": "tab:blue", "T_housing": "tab:green"}


def symbol(channel: str) -> str:
    """A channel's symbol in figures: the clutch's ϑ, any other model's channel name."""
    return SYMBOLS.get(channel, channel)


def label(channel: str) -> str:
    """A channel's title in figures."""
    return LABELS.get(channel, channel)


def colour(channel: str, index: int) -> str:
    """A channel's colour: the clutch's own, else the index-th of matplotlib's cycle."""
    return COLOURS.get(channel, f"C{index}")


def new_figure(width_in: float, height_in: float) -> Figure:
    """A constrained-layout figure on an Agg canvas (no display, no pyplot)."""
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def stride(n: int) -> int:
    """Step between plotted samples so that a line of n samples keeps at most MAX_POINTS."""
    return max(1, -(-n // MAX_POINTS))


def minutes(run: pd.DataFrame) -> np.ndarray:
    """The run's time axis in minutes (the report's time unit)."""
    return run["time"].to_numpy() / 60.0


def run_name(run: pd.DataFrame) -> str:
    """The run file's name for titles and tables (its path's last part)."""
    return Path(str(run.attrs.get("source", "run"))).name


def save(fig: Figure, path: "str | os.PathLike[str]") -> Path:
    """Write the figure as PNG (whole, then renamed into place: benchlab.outputs) and return its path."""
    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    return Path(path)
