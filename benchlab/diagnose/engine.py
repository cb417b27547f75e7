"""Find what the model gets wrong, name the cause, extend the model, measure the gain on held-out data.

Each run is cut into 10-minute blocks dealt alternately to two folds; a model is fitted on one
fold of every run and scored on the other, and the other way round (blocked cross-validation:
the scored samples were never fitted). Interleaving, not halves, so that each fit sees the whole
temperature range: a fit on one half extrapolates the slow housing dynamics into the other, and
its error then swamps the effects looked for (measured: held-out RMSE of the true model 0.028 K
with halves, 0.014 K interleaved, against 0.014 K in-sample).
Every candidate is screened by a short in-sample fit with all parameters free; the three best are
polished and cross-validated. An extension is accepted when its held-out error is lower by at
least MIN_GAIN_PCT and a t-test on the per-block log ratio of held-out errors (5-minute blocks,
not samples, are the units, so autocorrelated residuals do not inflate the evidence) rejects
"no gain" at ALPHA. Accepted extensions are combined greedily; with several, each is measured
again against the combination without it and dropped if it no longer gains.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd
from scipy import stats

from benchlab._blas import single_threaded_blas
from benchlab.diagnose.library import Candidate, candidates
from benchlab.diagnose.parallel import map_indices
from benchlab.identify.api import with_initial_states
from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import FitResult, fit, fit_multistart, simulate_outputs
from benchlab.identify.spec import ModelSpec
from benchlab.metrics import nrmse_pct, residual
from benchlab.model.build import build_spec
from benchlab.model.catalog import resolve_model
from benchlab.model.definition import ModelDefinition
from benchlab.progress import SILENT, Progress
from benchlab.runfile import ALIGNED_UNITS

STEP_S = 1.0
FOLD_S = 600.0
MIN_DURATION_S = 2 * FOLD_S  # one block in each fold
BLOCK_S = 300.0
MIN_GAIN_PCT = 5.0
ALPHA = 0.01
SCREEN_NFEV = 8
HELD_OUT_NFEV = 60
POLISH_NFEV = 200  # the all-data fit of a screened candidate: near convergence, so its gain is not underrated
CROSS_VALIDATED = 3
MAX_ROUNDS = 3
# The flywheel's temperature at t = 0 is fitted per run: a run that starts with a launch leaves one
# noisy reading to start from, and the fit then bends parameters (and spurious extensions gain
# 5-10 %) to absorb that start error. Air and housing start from a 10 s line fit (identify.data).
FITTED_STARTS = ("T_flywheel",)


def diagnosed_spec(model: ModelDefinition, datasets: Sequence[FitData]) -> ModelSpec:
    """What diagnose fits for a model: its parameters plus each run's fitted start of FITTED_STARTS channels."""
    spec = build_spec(model)
    starts = [c for c in FITTED_STARTS if c in set(spec.network.initial.values())]
    return with_initial_states(spec, datasets, starts) if starts else spec


@dataclass
class HeldOut:
    """Held-out predictions of one model: each sample simulated with the parameters of the fold that did not see it."""

    datasets: Sequence[FitData]
    predictions: list[dict[str, np.ndarray]]  # per run: channel -> simulated value at the fitting step
    params: list[dict[str, float]]  # per fold

    def residuals(self) -> list[dict[str, np.ndarray]]:
        """Simulated − measured (benchlab.metrics.residual) per run and channel; NaN where no valid target."""
        return [{c: residual(pred[c], d.targets[c]) for c in pred} for d, pred in zip(self.datasets, self.predictions)]

    @cached_property
    def _scored(self) -> tuple[np.ndarray, np.ndarray]:
        squared, blocks = [], []
        for run_index, (d, res) in enumerate(zip(self.datasets, self.residuals())):
            block_len = max(1, int(BLOCK_S / d.dt))
            for r in res.values():
                use = d.mask & np.isfinite(r)
                squared.append(r[use] ** 2)
                blocks.append(run_index * 10 ** 9 + np.flatnonzero(use) // block_len)
        return np.concatenate(squared), np.concatenate(blocks)

    @property
    def squared(self) -> np.ndarray:
        return self._scored[0]

    @property
    def blocks(self) -> np.ndarray:
        """The BLOCK_S block (of its run) each squared error belongs to: the units of the paired test."""
        return self._scored[1]

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.squared)))

    @property
    def nrmse_pct(self) -> float:
        """Contract §5: 100 · RMSE / (max − min of the measured signal) per channel, then averaged."""
        channels = list(self.predictions[0])
        measured = pd.DataFrame({c: np.concatenate([d.targets[c] for d in self.datasets]) for c in channels})
        simulated = pd.DataFrame({c: np.concatenate([p[c] for p in self.predictions]) for c in channels})
        return nrmse_pct(measured, simulated, channels)


@dataclass
class Finding:
    """An accepted extension, with the held-out errors of the model without it (before) and with it (after)."""

    candidate: Candidate
    spec: ModelSpec
    params: dict[str, float]
    added: tuple[str, ...]  # the parameters this extension brings
    before: HeldOut
    after: HeldOut
    p_value: float
    bic_delta: float  # in-sample BIC with the extension minus without it, on the effective sample size

    @property
    def gain_pct(self) -> float:
        return 100.0 * (1.0 - self.after.rmse / self.before.rmse)

    @property
    def significant(self) -> bool:
        """Held-out gain of at least MIN_GAIN_PCT, and "no gain" rejected at ALPHA."""
        return self.gain_pct >= MIN_GAIN_PCT and self.p_value < ALPHA


@dataclass
class Diagnosis:
    """The baseline, the accepted findings (largest gain first) and the final model, each with held-out predictions."""

    baseline: FitResult
    baseline_held: HeldOut
    findings: list[Finding]
    final: FitResult
    final_held: HeldOut


def _folds(datasets: Sequence[FitData]) -> list[tuple[list[FitData], list[FitData]]]:
    """Two (train, test) splits: FOLD_S blocks of every run dealt alternately to one fold and the other."""
    folds = []
    for fold in (0, 1):
        train, test = [], []
        for d in datasets:
            in_fold = (np.arange(len(d)) * d.dt // FOLD_S).astype(int) % 2 == fold
            train.append(d.with_mask(~in_fold))
            test.append(d.with_mask(in_fold))
        folds.append((train, test))
    return folds


def _held_out(spec: ModelSpec, start: dict[str, float], datasets: Sequence[FitData]) -> HeldOut:
    """Fit on each fold's training blocks (warm-started at `start`) and predict its test blocks."""
    predictions = [{c: np.full(len(d), np.nan) for c in d.targets} for d in datasets]
    params = []
    for train, test in _folds(datasets):
        result = fit(spec, train, max_nfev=HELD_OUT_NFEV, start={p.name: start[p.name] for p in spec.free})
        params.append(result.params)
        for pred, d in zip(predictions, test):
            for c, values in simulate_outputs(spec.network, result.params, d).items():
                pred[c][d.mask] = values[d.mask]
    return HeldOut(datasets, predictions, params)


def _bic_delta(cost_before: float, cost_after: float, residuals_after: np.ndarray, added: int) -> float:
    """In-sample BIC change of an extension (negative favours it), second to the held-out test.

    The sample size is the effective one of the residuals, n (1 − ρ) / (1 + ρ) with ρ their lag-1
    autocorrelation: 1 s residuals of a thermal model are far from independent.
    """
    r = residuals_after
    rho = float(np.clip(np.corrcoef(r[:-1], r[1:])[0, 1], 0.0, 0.99)) if len(r) > 2 else 0.0
    n_eff = max(2.0, len(r) * (1 - rho) / (1 + rho))
    return float(n_eff * np.log(cost_after / cost_before) + added * np.log(n_eff))


def _block_test(before: HeldOut, after: HeldOut) -> float:
    """One-sided p-value that the extension does not lower the held-out error, blocks as units.

    The t-test is on each block's log ratio of mean squared errors: scale-free, so a few blocks
    where the error was large (a missed heat source after every launch) do not swamp the rest.
    """
    _, inverse = np.unique(before.blocks, return_inverse=True)
    count = np.bincount(inverse)
    log_ratio = np.log(np.bincount(inverse, before.squared) / count) - np.log(np.bincount(inverse, after.squared) / count)
    if len(log_ratio) < 3 or np.allclose(log_ratio, 0):
        return 1.0
    return float(stats.ttest_1samp(log_ratio, 0.0, alternative="greater").pvalue)


Screened = tuple[float, Candidate, ModelSpec, dict[str, float]]  # in-sample cost, candidate, its spec, fitted values


def _screen(cands: Sequence[Candidate], current: FitResult, datasets: Sequence[FitData],
            channels: dict[str, np.ndarray], progress: Progress, what: str) -> list[Screened]:
    """A short in-sample fit of each candidate, every parameter free, from the current model; by cost, best first.

    Every parameter, not only the new ones: a model that lacks an effect has bent its other
    parameters to absorb it, and the new term pays off only once they are released (a plate share
    of 0.35 screened alone lowered the cost by 0 %, with all parameters free by 40 %).
    """
    specs = [diagnosed_spec(cand.build(current.spec.definition, channels), datasets) for cand in cands]

    def screen_one(i: int) -> tuple[float, dict[str, float]]:
        result = fit(specs[i], datasets, max_nfev=SCREEN_NFEV,
                     start={**{p.name: p.initial for p in specs[i].free},
                            **{k: current.params[k] for k in current.free_names}})
        return result.cost, result.params

    with progress.task(what, len(specs), unit="fit") as task:
        screened = map_indices(screen_one, len(specs), task.advance)
    scored = [(cost, cand, spec, params) for cand, spec, (cost, params) in zip(cands, specs, screened)
              if cost < current.cost]
    return sorted(scored, key=lambda item: item[0])


def _try(scored: Sequence[Screened], current: FitResult, current_held: HeldOut,
         datasets: Sequence[FitData]) -> Finding | None:
    """Polish and cross-validate the best-screened candidates; the significant one with the largest gain, if any."""
    start_names = set(current.free_names)
    top = scored[:CROSS_VALIDATED]

    def validate(i: int) -> tuple[dict[str, float], float, np.ndarray, HeldOut]:
        _, _, spec, params = top[i]
        result = fit(spec, datasets, max_nfev=POLISH_NFEV, start={p.name: params[p.name] for p in spec.free})
        return result.params, result.cost, result.residuals, _held_out(spec, result.params, datasets)

    best: Finding | None = None
    for (_, cand, spec, _), (params, cost, residuals, held) in zip(top, map_indices(validate, len(top))):
        added = tuple(p.name for p in spec.free if p.name not in start_names)
        finding = Finding(cand, spec, params, added, current_held, held, _block_test(current_held, held),
                          _bic_delta(current.cost, cost, residuals, len(added)))
        if finding.significant and (best is None or finding.gain_pct > best.gain_pct):
            best = finding
    return best


def _combined(base: ModelSpec, cands: Sequence[Candidate], channels: dict[str, np.ndarray],
              datasets: Sequence[FitData]) -> ModelSpec:
    """The baseline with the given extensions applied in order."""
    model = base.definition
    for cand in cands:
        model = cand.build(model, channels)
    return diagnosed_spec(model, datasets)


def _recheck(base: FitResult, base_held: HeldOut, findings: Sequence[Finding], final: FitResult,
             final_held: HeldOut, datasets: Sequence[FitData], channels: dict[str, np.ndarray]) -> list[Finding]:
    """Each accepted extension measured against the final model without it (drop-one, held out).

    The greedy steps measured each gain on top of the ones found before it; with several findings
    the fair figure is what the combined model loses without it.
    """
    def without(i: int) -> tuple[float, HeldOut]:
        others = [g.candidate for g in findings if g is not findings[i]]
        if not others:
            return base.cost, base_held
        spec = _combined(base.spec, others, channels, datasets)
        refit = fit(spec, datasets, max_nfev=HELD_OUT_NFEV, start={p.name: final.params[p.name] for p in spec.free})
        return refit.cost, _held_out(spec, refit.params, datasets)

    return [Finding(f.candidate, final.spec, final.params, f.added, held, final_held, _block_test(held, final_held),
                    _bic_delta(cost, final.cost, final.residuals, len(f.added)))
            for f, (cost, held) in zip(findings, map_indices(without, len(findings)))]


@single_threaded_blas
def diagnose_runs(runs: Sequence[pd.DataFrame], baseline: "str | ModelDefinition" = "linear", starts: int = 4,
                  seed: int = 0, progress: Progress = SILENT) -> Diagnosis:
    """Baseline fit, greedy accepted extensions, then a drop-one re-check of each against the combination.

    `baseline`: a built-in name, a model file or a checked model; every extension is an edit of it.
    `progress` gets a task for the baseline's multistart and one per screening of candidates.
    """
    duration = sum(float(run["time"].iloc[-1] - run["time"].iloc[0]) for run in runs)
    if duration < MIN_DURATION_S:
        raise ValueError(f"diagnose needs at least {MIN_DURATION_S:.0f} s of runs for held-out scoring, "
                         f"got {duration:.0f} s")
    model = baseline if isinstance(baseline, ModelDefinition) else resolve_model(baseline)
    network = build_spec(model).network
    datasets = [prepare(run, STEP_S, name=str(i), network=network) for i, run in enumerate(runs)]
    shared = set.intersection(*(set(d.channels) for d in datasets))
    channels = {k: np.concatenate([d.channels[k] for d in datasets]) for k in datasets[0].channels if k in shared}
    units = {**ALIGNED_UNITS, **runs[0].attrs.get("units", {})}
    with progress.task(f"diagnose: {model.label} baseline", starts + 1, unit="fit") as task:
        base = fit_multistart(diagnosed_spec(model, datasets), datasets, starts=starts, seed=seed, task=task)
    base_held = _held_out(base.spec, base.params, datasets)
    library = candidates(model, channels, units)
    current, current_held, findings = base, base_held, []
    for round_ in range(1, MAX_ROUNDS + 1):
        used = {f.candidate.key for f in findings}
        remaining = [c for c in library if c.key not in used]
        finding = _try(_screen([c for c in remaining if c.physical], current, datasets, channels, progress,
                               f"diagnose round {round_}: mechanisms"), current, current_held, datasets)
        if finding is None:
            finding = _try(_screen([c for c in remaining if not c.physical], current, datasets, channels, progress,
                                   f"diagnose round {round_}: learned flows"), current, current_held, datasets)
        if finding is None:
            break
        findings.append(finding)
        current = fit(finding.spec, datasets, start={p.name: finding.params[p.name] for p in finding.spec.free})
        current_held = finding.after
    dropped = False
    while len(findings) > 1 or (findings and dropped):  # until every finding holds against the rest (alpha, gain)
        findings = _recheck(base, base_held, findings, current, current_held, datasets, channels)
        kept = [f for f in findings if f.significant]
        if len(kept) == len(findings):
            break
        dropped = True  # another finding covered what this one fixed: drop it, measure the rest again
        if not kept:
            current, current_held, findings = base, base_held, []
            break
        spec = _combined(base.spec, [f.candidate for f in kept], channels, datasets)
        current = fit(spec, datasets, start={p.name: current.params[p.name] for p in spec.free})
        current_held, findings = _held_out(spec, current.params, datasets), kept
    return Diagnosis(base, base_held, sorted(findings, key=lambda f: -f.gain_pct), current, current_held)
