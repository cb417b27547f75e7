"""The two models a diagnosis leaves competing, rebuilt from its JSON and refitted to the runs so far.

A finding with alternatives (diagnose's tie) gives the finding's extension against its first alternative, both on
the same parent (the baseline with the findings of earlier rounds); a finding without one gives the cause against
its parent. The extensions are rebuilt from the library by their candidate keys (`benchlab.diagnose.library`) and
fitted as diagnose fits a finding (`engine.refit_candidate`: screened from a start where the extension acts,
polished with a scout from the neutral start, refitted whole), not from the nested start alone, where an extension
whose new parameters are flat (a bridge's node of 1 J/K) stays inert and predicts the parent's run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.design.discrimination import Rival, misfit
from benchlab.diagnose.engine import (STEP_S, diagnosed_spec, extended_spec, level_channels, library_for,
                                      refit_candidate)
from benchlab.diagnose.library import Candidate
from benchlab.errors import InputError
from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import fit_multistart
from benchlab.model.build import build_spec
from benchlab.model.catalog import resolve_model
from benchlab.model.definition import ModelDefinition
from benchlab.runfile import ALIGNED_UNITS

#: Starts of the parent's multistart fit (diagnose's baseline uses 4; the parent only seeds the rivals' fits).
PARENT_STARTS = 2


@dataclass(frozen=True)
class Contest:
    """What a diagnosis leaves open: the parent model's candidates applied in order, then the two contenders
    (None: the parent itself)."""

    baseline: str
    parent: tuple[str, ...]
    favoured: str
    other: str | None


def contest(doc: dict, source: str) -> Contest:
    """The first tied finding (findings, then leads), else the first finding against its parent. InputError where
    the diagnosis has no finding."""
    try:
        baseline = doc["baseline"]["model"]
        found = [*doc.get("findings", []), *doc.get("leads", [])]
        rounds = [(int(f.get("round") or 0), f["candidate"]) for f in doc.get("findings", [])]
    except (KeyError, TypeError, ValueError):
        raise InputError(source, "baseline/findings", "a diagnose JSON (benchlab diagnose --out)") from None
    if not found:
        raise InputError(source, "findings", "at least one finding or lead: nothing is left open to tell apart")
    tied = next((f for f in found if f.get("alternatives")), found[0])
    own = int(tied.get("round") or 0)
    parent = tuple(key for r, key in sorted(rounds) if r < own and key != tied["candidate"])
    other = tied["alternatives"][0]["candidate"] if tied.get("alternatives") else None
    return Contest(baseline, parent, tied["candidate"], other)


def baseline_model(plan: Contest, source: str) -> ModelDefinition:
    """The diagnosis's baseline model, or InputError naming the diagnosis."""
    try:
        return resolve_model(plan.baseline)
    except (OSError, ValueError) as exc:
        raise InputError(source, "baseline.model", f"a built-in model or a model file ({exc})") from None


def refitted_rivals(doc: dict, source: str, runs: Sequence[pd.DataFrame], seed: int = 0) -> tuple[Rival, Rival, list[FitData]]:
    """The two contenders of `doc` (a diagnose JSON) refitted to `runs`, the favoured (the named finding) first, and
    the runs as they were fitted (diagnose's step)."""
    plan = contest(doc, source)
    model = baseline_model(plan, source)
    network = build_spec(model).network
    datasets = [prepare(run, STEP_S, name=str(i), network=network) for i, run in enumerate(runs)]
    shared = set.intersection(*(set(d.channels) for d in datasets))
    channels = {k: np.concatenate([d.channels[k] for d in datasets]) for k in datasets[0].channels if k in shared}
    units = {**ALIGNED_UNITS, **runs[0].attrs.get("units", {})}
    levels = level_channels(datasets, network.measured)
    library = {c.key: c for c in library_for(model, channels, units, datasets, levels=levels)}

    def candidate(key: str) -> Candidate:
        if key not in library:
            raise InputError(source, "candidate", f"an extension of {plan.baseline} on these runs, got {key!r}")
        return library[key]

    ancestors = [candidate(key) for key in plan.parent]  # every key checked before the first fit
    favoured, other = candidate(plan.favoured), None if plan.other is None else candidate(plan.other)
    spec = diagnosed_spec(model, datasets)
    for ancestor in ancestors:
        spec = extended_spec(spec, ancestor, channels, datasets)
    parent = fit_multistart(spec, datasets, starts=PARENT_STARTS, seed=seed)

    def rival(cand: Candidate | None) -> Rival:
        if cand is None:
            return Rival(f"{plan.baseline} without {plan.favoured}", parent.spec, parent.params,
                         *misfit(parent.spec.network, parent.params, datasets))
        result = refit_candidate(cand, parent, datasets, channels, seed + 1)
        return Rival(cand.key, result.spec, result.params, *misfit(result.spec.network, result.params, datasets))

    return rival(favoured), rival(other), datasets
