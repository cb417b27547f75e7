"""Eq. (11) as the cool-down sweep measures it, against the model identified from Table 1, and the paper's procedure.

Table 1 varies the engine speed only between 1000 and 2000 rpm and opens the clutch for at most two minutes at a
time: the open-clutch branch of eq. (11) barely moves the measured channels, and a fit of Table 1 alone leaves it
unidentified (`benchlab.identify.identifiability`). The paper took the nonlinearity from steady cool-downs at fixed
operating points (its Fig. 3). Here each cool-down of the sweep gives R at its operating point with the other
parameters of the Table 1 model (`benchlab.identify.cooldown.analyse`: R and the plate's start free per segment; the
points do not depend on eq. (11)'s own parameters), and two things are measured:

* how far the Table 1 model's R(ω_e, S) lies from those points (`eq11_rel_error`): the sweep's verdict on eq. (11);
* the paper's procedure: eq. (11) fitted to the points and held, every other parameter fitted to the runs again
  (`sweep_model`); whether it predicts unseen runs better than the Table 1 model is for the caller to measure.

A model identified with the sweep among its runs (the main job's diagnosis of Table 1 and the sweep together) is
measured against the points as it reads them itself (`own_points_error`): its own structure and values in each
segment's fit, so that eq. (11)'s R is not held against points that another model's links made. Fitted jointly,
such a model trades eq. (11) against the runs' other samples (14-20 % from its own points on the reference plant,
where eq. (11) fitted to those points alone is within 5-14 %); `held_to_own_points` is the paper's procedure on its
structure: eq. (11) from the points it reads, held, the rest refitted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.identify.api import Identification, identify
from benchlab.identify.cooldown import CooldownResult, analyse, fit_eq11, segment_model
from benchlab.model.clutch import convection_resistance
from benchlab.model.params import ModelParams
from benchlab.progress import SILENT, Progress

#: eq. (11)'s parameters, which the sweep's points pin in the paper's procedure
EQ11 = ("a1", "b1", "a2", "b2", "R0")
#: the engine speeds at which the issue's and the page's comparison is made (Fig. 3's two ends of Table 1's range)
COMPARED_RPM = (1000.0, 2500.0)


@dataclass
class SweepComparison:
    """The sweep's points, eq. (11) fitted to them (None where the grid cannot determine it), the Table 1 model's
    largest relative error against them, and the model of the paper's procedure (None without an eq. (11) fit)."""

    points: list[CooldownResult]
    eq11: dict[str, float] | None
    rel_error: float
    sweep_model: Identification | None


def resistance_at(params: "dict[str, float]", points: Sequence[CooldownResult]) -> np.ndarray:
    """The model's R(ω_e, S) of eq. (11) at each cool-down's operating point."""
    channels = {"engine_speed": np.array([c.engine_speed for c in points], float),
                "clutch_state": np.array([float(c.clutch_state) for c in points])}
    return np.broadcast_to(np.asarray(convection_resistance(params, channels), float), (len(points),)).copy()


def eq11_rel_error(params: "dict[str, float]", points: Sequence[CooldownResult],
                   speeds: Sequence[float] = COMPARED_RPM) -> float:
    """Largest |R_model / R_sweep - 1| over the sweep's points at `speeds` (both clutch states); NaN without any."""
    chosen = [c for c in points if any(abs(c.engine_speed - s) < 1.0 for s in speeds) and np.isfinite(c.R)]
    if not chosen:
        return float("nan")
    measured = np.array([c.R for c in chosen], float)
    return float(np.max(np.abs(resistance_at(params, chosen) / measured - 1.0)))


def own_points_error(sweep: "str | Path", params: ModelParams, progress: Progress = SILENT,
                     sweep_run: pd.DataFrame | None = None) -> tuple[list[CooldownResult], float]:
    """The sweep's points read with `params`' own model (benchlab.identify.cooldown.segment_model) and the largest
    relative error of that model's eq. (11) against them (eq11_rel_error). `sweep_run`: the sweep already loaded
    (benchlab.identify.cooldown.analyse)."""
    points = analyse(sweep, params, progress=progress, model=segment_model(params), run=sweep_run)
    return points, eq11_rel_error(params, points)


def compare_with_sweep(runs: Sequence[pd.DataFrame], params: ModelParams, sweep: "str | Path",
                       validate: Sequence[pd.DataFrame] = (), starts: int = 4, seed: int = 0,
                       progress: Progress = SILENT, sweep_run: pd.DataFrame | None = None) -> SweepComparison:
    """The sweep's points with the Table 1 model `params` (identified on `runs`), its eq. (11) against them, and the
    paper's procedure on the same runs (eq. (11) from the points held, the rest refitted). `sweep_run`: the sweep
    already loaded (benchlab.identify.cooldown.analyse)."""
    points = analyse(sweep, params, progress=progress, run=sweep_run)
    try:
        eq11 = fit_eq11(points)
    except ValueError:
        return SweepComparison(points, None, eq11_rel_error(params, points), None)
    fixed = {k: eq11[k] for k in EQ11}
    model = identify(runs, params.definition, fixed=fixed, validate=validate, starts=starts, seed=seed,
                     progress=progress)
    return SweepComparison(points, eq11, eq11_rel_error(params, points), model)


def held_to_own_points(runs: Sequence[pd.DataFrame], params: ModelParams, sweep: "str | Path",
                       points: Sequence[CooldownResult], validate: Sequence[pd.DataFrame] = (), starts: int = 2,
                       seed: int = 0, progress: Progress = SILENT,
                       sweep_run: pd.DataFrame | None = None) -> tuple[Identification, float] | None:
    """The paper's procedure on `params`' own structure (module doc): eq. (11) fitted to `points` (the sweep as
    that model reads it, `own_points_error`) and held, every other parameter refitted on `runs`; the refitted model
    and its eq. (11)'s largest relative error against the points it reads itself. None where the points cannot
    determine eq. (11). `sweep_run`: the sweep already loaded (benchlab.identify.cooldown.analyse)."""
    try:
        eq11 = fit_eq11(points)
    except ValueError:
        return None
    model = identify(runs, params.definition, fixed={k: eq11[k] for k in EQ11}, validate=validate, starts=starts,
                     seed=seed, progress=progress)
    return model, own_points_error(sweep, model.params, progress, sweep_run)[1]
