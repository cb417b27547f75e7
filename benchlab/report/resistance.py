"""Fig. 3 of the paper: convection resistance R_FA = R_PA (eq. 11) against engine speed for both clutch states,
with the per-cool-down estimates of a cooldown-sweep run (benchlab.identify.cooldown) where one is given."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchlab.identify.identifiability import recorded
from benchlab.model.clutch import convection_resistance
from benchlab.identify.cooldown import COVERAGE_K, CooldownResult
from benchlab.model.params import ModelParams
from benchlab.report.plotting import MODEL_STYLES, new_figure, save
from benchlab.values import finite_number

SPEED_MAX_RPM = 3000.0
#: clutch state -> (legend text, colour, the eq. (11) parameters of that state)
STATES = {1: ("clutch closed (S = 1)", "tab:red", ("a1", "b1")), 0: ("clutch open (S = 0)", "tab:blue", ("a2", "b2"))}


def has_convection_law(params: ModelParams) -> bool:
    """Whether the parameters are a clutch model's with eq. (11) (a linear one means a1 = a2 = 0)."""
    return all(name in params for name in ("R0", "a1", "b1", "a2", "b2"))


def standard_errors(params: ModelParams) -> dict[str, float]:
    """The parameter file's "uncertainty" object (name -> standard error, as identify writes it); numbers only."""
    found = params.extra.get("uncertainty")
    if not isinstance(found, dict):
        return {}
    numbers = {k: finite_number(v) for k, v in found.items()}
    return {k: v for k, v in numbers.items() if v is not None}


def correlations(params: ModelParams) -> dict[tuple[str, str], float]:
    """The parameter file's "correlation" object (names and matrix, as identify writes it) as pairs, its finite
    entries only; {} if absent."""
    found = params.extra.get("correlation")
    try:
        names, matrix = list(found["names"]), np.asarray(found["matrix"], dtype=float)
    except (TypeError, KeyError, ValueError):
        return {}
    if matrix.shape != (len(names), len(names)):
        return {}
    return {(a, b): float(matrix[i, j]) for i, a in enumerate(names) for j, b in enumerate(names)
            if math.isfinite(matrix[i, j])}  # none for a parameter without a standard error


def resistance(params: ModelParams, speed_rpm: np.ndarray, state: int) -> tuple[np.ndarray, np.ndarray]:
    """R (K/W) of eq. (11) at the engine speeds and its standard error by the delta method, with the file's
    parameter correlations where it holds them (a1 and R0 are strongly anti-correlated: ignoring that
    widens the band several times)."""
    speed = np.asarray(speed_rpm, dtype=float)
    channels = {"engine_speed": speed, "clutch_state": np.full_like(speed, float(state))}
    value = np.broadcast_to(convection_resistance(params, channels), speed.shape)
    se, corr = standard_errors(params), correlations(params)
    a, b = STATES[state][2]
    growth = np.exp(params[b] * speed)
    slopes = {a: growth, b: params[a] * speed * growth, "R0": np.ones_like(speed)}
    variance = np.zeros_like(speed)
    for i, slope_i in slopes.items():
        for j, slope_j in slopes.items():
            rho = 1.0 if i == j else corr.get((i, j), 0.0)
            variance = variance + slope_i * slope_j * rho * se.get(i, 0.0) * se.get(j, 0.0)
    return value, np.sqrt(np.maximum(variance, 0.0))


def y_top(curves: Sequence[np.ndarray], measured: Sequence[float]) -> float:
    """The top of Fig. 3's y-axis: the highest identified curve or measured point (its error bar included) with a
    tenth to spare. The ±2 SE bands do not set it: a band of parameters the runs barely pin reached 175 K/W and
    squashed every curve and point onto the axis."""
    highest = [float(np.nanmax(c)) for c in curves if np.any(np.isfinite(c))]
    highest += [float(v) for v in measured if math.isfinite(v)]
    return 1.1 * max(highest) if highest and max(highest) > 0 else 1.0


def plot_resistance(models: Sequence[tuple[str, ModelParams]], cooldowns: Sequence[CooldownResult],
                    path: "str | os.PathLike[str]") -> Path:
    """Eq. (11) of each model for S = 1 and S = 0, sweep points on top; the y-range from the curves and the points.
    A ±2 SE band (where the file has standard errors) is drawn where it says something: not for a law whose
    parameters the runs do not identify, and not where it is wider than the plotted range; the legend says which
    was left out and why."""
    top_speed = max([SPEED_MAX_RPM] + [1.1 * r.engine_speed for r in cooldowns])
    speed = np.linspace(0.0, top_speed, 301)
    fig = new_figure(9, 7.5)
    ax = fig.subplots()
    drawn, bands = [], []
    for (label, params), (_, style) in zip(models, MODEL_STYLES):
        curves = {state: resistance(params, speed, state) for state in STATES}
        if np.allclose(curves[0], curves[1]):  # one law for both states (a linear model: R0 alone)
            curves = {None: curves[1]}
        for state, (value, sigma) in curves.items():
            text, colour, law = STATES[state] if state is not None else ("both clutch states", "k", STATES[1][2])
            ax.plot(speed, value, color=colour, ls=style, lw=1.4, label=f"{label} model, {text}")
            drawn.append(value)
            if np.any(sigma > 0):
                bands.append((f"{label} model, {text}", params, value, sigma, colour, ("R0", *law)))
    measured = []
    for state, (text, colour, _) in STATES.items():
        points = [r for r in cooldowns if r.clutch_state == state]
        if points:
            ax.errorbar([r.engine_speed for r in points], [r.R for r in points], yerr=[r.R_u for r in points],
                        fmt="o", color=colour, capsize=3, label=f"cool-down fit, {text} (±U, k = {COVERAGE_K:g})")
            measured += [r.R + r.R_u for r in points]
    truth = [r for r in cooldowns if math.isfinite(r.R_true)]
    if truth:
        ax.scatter([r.engine_speed for r in truth], [r.R_true for r in truth], marker="x", color="k", zorder=5,
                   label="simulated bench's true R")
        measured += [r.R_true for r in truth]
    top = y_top(drawn, measured)
    for text, params, value, sigma, colour, law in bands:
        _band(ax, speed, text, params, value, sigma, colour, law, top)
    ax.set(xlabel=r"engine speed $\omega_e$ (rpm)", ylabel=r"$R_{FA} = R_{PA}$ (K/W)", xlim=(0.0, top_speed),
           ylim=(0.0, top))
    ax.grid(alpha=0.3)
    fig.legend(loc="outside lower center", fontsize=8)  # below the axes: no point hidden behind it
    ax.set_title("Fig. 3 – convection resistance inside the clutch chamber, eq. (11), against engine speed")
    return save(fig, path)


def _band(ax, speed: np.ndarray, text: str, params: ModelParams, value: np.ndarray, sigma: np.ndarray,
          colour: str, law: Sequence[str], top: float) -> None:
    """One law's ±2 SE band where it fits the plotted range, or, in the legend, why it was left out."""
    unidentified = [name for name in law if name in recorded(params)]
    fits = value + 2 * sigma <= top
    if unidentified:
        why = f"{', '.join(unidentified)} not identified by the runs"
    elif not np.any(fits):
        why = "wider than the plotted range"
    else:
        where = "" if np.all(fits) else ", left out where wider than the plotted range"
        ax.fill_between(speed, value - 2 * sigma, value + 2 * sigma, where=fits, color=colour, alpha=0.12,
                        label=f"{text} ±2 SE{'' if correlations(params) else ' (correlations ignored)'}{where}")
        return
    ax.plot([], [], " ", label=f"{text}: ±2 SE band left out ({why})")
