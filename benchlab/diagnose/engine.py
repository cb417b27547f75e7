"""Find what the model gets wrong, name the cause, extend the model, measure the gain on held-out data.

Each run is cut into two halves; a model is fitted on one half of every run and scored on the
other, and the other way round (blocked cross-validation: the scored samples were never fitted).
Candidates are first screened by an in-sample fit from the current model; the most promising
are cross-validated. An extension is accepted when its held-out error is lower by at least
MIN_GAIN_PCT and a paired t-test over 5-minute blocks of held-out data rejects "no gain" at
the 1 % level (blocks, not samples, are the units, so autocorrelated residuals do not inflate
the evidence). Accepted extensions are combined greedily and the rest re-checked on top.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from benchlab.diagnose.library import Candidate, candidates
from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import FitResult, fit, fit_multistart, simulate_outputs
from benchlab.identify.spec import ModelSpec, clutch_spec

STEP_S = 1.0
BLOCK_S = 300.0
MIN_GAIN_PCT = 5.0
ALPHA = 0.01
SCREEN_NFEV = 15
HELD_OUT_NFEV = 60
CROSS_VALIDATED = 3
MAX_ROUNDS = 3


@dataclass
class HeldOut:
    """Held-out squared errors of one model, with the 10-minute block each belongs to."""

    squared: np.ndarray
    blocks: np.ndarray
    params: list[dict[str, float]]

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.squared)))


@dataclass
class Finding:
    candidate: Candidate
    spec: ModelSpec
    params: dict[str, float]
    before: HeldOut
    after: HeldOut
    p_value: float

    @property
    def gain_pct(self) -> float:
        return 100.0 * (1.0 - self.after.rmse / self.before.rmse)


def _halves(datasets: Sequence[FitData]) -> list[tuple[list[FitData], list[FitData]]]:
    folds = []
    for first in (True, False):
        train, test = [], []
        for d in datasets:
            in_first = np.arange(len(d)) < len(d) // 2
            train.append(d.with_mask(in_first if first else ~in_first))
            test.append(d.with_mask(~in_first if first else in_first))
        folds.append((train, test))
    return folds


def _held_out(spec: ModelSpec, start: dict[str, float], datasets: Sequence[FitData]) -> HeldOut:
    squared, blocks, params = [], [], []
    block_len = max(1, int(BLOCK_S / datasets[0].dt))
    offset = 0
    for train, test in _halves(datasets):
        result = fit(spec, train, max_nfev=HELD_OUT_NFEV, start={p.name: start[p.name] for p in spec.free})
        params.append(result.params)
        for run_index, d in enumerate(test):
            sim = simulate_outputs(spec.network, result.params, d)
            for c, target in d.targets.items():
                use = d.mask & np.isfinite(target)
                squared.append((sim[c][use] - target[use]) ** 2)
                blocks.append(offset + run_index * 10 ** 6 + np.flatnonzero(use) // block_len)
        offset += 10 ** 9
    return HeldOut(np.concatenate(squared), np.concatenate(blocks), params)


def _block_test(before: HeldOut, after: HeldOut) -> float:
    """One-sided p-value that the extension does not lower the held-out error, blocks as units."""
    labels, inverse = np.unique(before.blocks, return_inverse=True)
    diff = np.bincount(inverse, before.squared - after.squared) / np.bincount(inverse)
    if len(diff) < 3 or np.allclose(diff, 0):
        return 1.0
    return float(stats.ttest_1samp(diff, 0.0, alternative="greater").pvalue)


def _screen(cands: Sequence[Candidate], current: FitResult, datasets: Sequence[FitData],
            channels: dict[str, np.ndarray]) -> list[tuple[float, Candidate, FitResult]]:
    """In-sample fit of each candidate's new parameters, the current model held; sorted by cost, best first."""
    scored = []
    known = {p.name for p in current.spec.free}
    for cand in cands:
        spec = cand.build(current.spec, channels)
        screening = spec.with_fixed({k: current.params[k] for k in known if k not in cand.touches})
        screening = screening.starting_point({k: current.params[k] for k in known})
        result = fit(screening, datasets, max_nfev=SCREEN_NFEV)
        if result.cost < current.cost:
            scored.append((result.cost, cand, FitResult(spec, result.params, result.cost, result.rmse_k,
                                                        result.n_residuals, result.jacobian, result.residuals)))
    return sorted(scored, key=lambda item: item[0])


def _try(scored, current_held: HeldOut, datasets) -> Finding | None:
    best: Finding | None = None
    for _, cand, screened in scored[:CROSS_VALIDATED]:
        result = fit(screened.spec, datasets, max_nfev=HELD_OUT_NFEV,
                     start={p.name: screened.params[p.name] for p in screened.spec.free})
        held = _held_out(result.spec, result.params, datasets)
        finding = Finding(cand, result.spec, result.params, current_held, held, _block_test(current_held, held))
        if finding.gain_pct >= MIN_GAIN_PCT and finding.p_value < ALPHA:
            if best is None or finding.gain_pct > best.gain_pct:
                best = finding
    return best


def diagnose_runs(runs: Sequence[pd.DataFrame], baseline: str = "linear", starts: int = 4,
                  seed: int = 0) -> tuple[FitResult, HeldOut, list[Finding], FitResult]:
    """Baseline fit, then greedy accepted extensions; returns (baseline, its held-out error, findings, final)."""
    datasets = [prepare(run, STEP_S, name=str(i)) for i, run in enumerate(runs)]
    channels = {k: np.concatenate([d.channels[k] for d in datasets]) for k in datasets[0].channels}
    base = fit_multistart(clutch_spec(baseline), datasets, starts=starts, seed=seed)
    base_held = _held_out(base.spec, base.params, datasets)
    library = candidates(baseline_is_linear=baseline == "linear")
    current, current_held, findings = base, base_held, []
    for _ in range(MAX_ROUNDS):
        used = {f.candidate.key for f in findings}
        remaining = [c for c in library if c.key not in used]
        finding = _try(_screen([c for c in remaining if c.physical], current, datasets, channels),
                       current_held, datasets)
        if finding is None:
            finding = _try(_screen([c for c in remaining if not c.physical], current, datasets, channels),
                           current_held, datasets)
        if finding is None:
            break
        findings.append(finding)
        current = fit(finding.spec, datasets, start={p.name: finding.params[p.name] for p in finding.spec.free})
        current_held = finding.after
    return base, base_held, findings, current
