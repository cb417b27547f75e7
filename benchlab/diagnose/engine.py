"""Find what the model gets wrong, name the cause, extend the model, measure the gain on held-out data.

Each run is cut into 10-minute blocks dealt alternately to two folds; a model is fitted on one
fold of every run and scored on the other, and the other way round (blocked cross-validation:
the scored samples were never fitted). Interleaving, not halves, so that each fit sees the whole
temperature range: a fit on one half extrapolates the slow housing dynamics into the other, and
its error then swamps the effects looked for (measured: held-out RMSE of the true model 0.028 K
with halves, 0.014 K interleaved, against 0.014 K in-sample).

Each round: every candidate of the generated library (benchlab.diagnose.library) starts nested, at the
current model. A score test ranks the ones whose effect is first order there: the cost one Gauss-Newton
step would reach with every parameter free (the linearised fit, the current model's parameters released
with the new ones, so an effect the model absorbed by bending them still shows); the SCORED_FITS best and
every structural candidate (extra nodes, lags) then get a short fit from the nested start, which can only
lower the parent's cost. The CROSS_VALIDATED best of those are fitted to convergence from the warm start and
from the model file's neutral start, and cross-validated from the better one; a fit with a parameter on its
bound has failed (reported, not used). An extension is accepted when its held-out error is lower by at least
MIN_GAIN_PCT and a t-test on the per-block log ratio of held-out errors (5-minute blocks, not samples, are
the units) rejects "no gain" at ALPHA. Of the extensions that pass, the largest gain is named only where the
same test shows it better than each simpler explanation (fewer added parameters, then fewer signals); otherwise
the simplest is. Where another candidate is not significantly worse than the named one by the same test, the
finding lists it as an alternative. After each acceptance the whole model is
refitted with multistart (warm, neutral and spread starts), so the next round starts from a fresh global fit,
not from the parameters the previous round bent. With several findings, each is measured again against the
combination without it and dropped if it no longer passes; no finding is reported that did not pass. Last, a
finding is named as a cause only where the final fit identifies the parameters it adds and, with runs no fit saw
(`validate`), its gain carries to them by the same rule; any other is a lead, taken out one at a time (_causes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import pandas as pd
from scipy import stats

from benchlab._blas import single_threaded_blas
from benchlab.diagnose.library import (Candidate, applies, candidates, carried_values, composed_links,
                                      per_group_candidates)
from benchlab.diagnose.parallel import map_indices
from benchlab.identify.api import with_initial_states
from benchlab.identify.data import FitData, prepare
from benchlab.identify.identifiability import not_identified, on_bound
from benchlab.identify.fit import (FitResult, arrived, coordinate_bounds, fit, fit_multistart, from_coordinates,
                                   residual_vector, simulate_outputs, to_coordinates)
from benchlab.identify.spec import ModelSpec, ParamSpec
from benchlab.identify.metrics import difference_noise, nrmse_pct, residual
from benchlab.identify.uncertainty import estimate_uncertainty
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
SCORE_STEP = 0.05  # forward-difference step of a new parameter's column, in fitted coordinates
SCORED_FITS = 6  # best-scored candidates screened by a short fit
STRUCTURAL_FITS = 3  # best-scored extra nodes and lags screened by a short fit beside them
#: best-scored explanations among the two-step candidates (a new link with its per-run split or a signal law), each
#: with all its laws, screened beside them
COMPOSED_FITS = 2
#: a screened composition goes on only below this share of the best one-step candidate's screened cost: the second
#: step must promise the MIN_GAIN_PCT a finding needs beyond what one step already reaches, else the simpler one
#: would be named before it anyway (it cannot be significantly better held out)
COMPOSED_MARGIN = (1.0 - MIN_GAIN_PCT / 100.0) ** 2
#: best-scored switch with hysteresis screened by a short fit beside them: its score is taken with its thresholds
#: where its screening start put them, and where they are only near, the first step says little
SWITCH_FITS = 1
SCREEN_NFEV = 8
HELD_OUT_NFEV = 60
#: a held-out (cross-validation) fit starts at the all-data fit's optimum and stops once a step changes the cost, the
#: parameters or the gradient by less than this share: what it predicts moves far below the noise floor from there
HELD_OUT_TOLERANCE = 1e-6
#: ... or once its last HELD_OUT_STALL[0] steps together lowered the cost by less than HELD_OUT_STALL[1] of it: a fold
#: fit crawling along a valley of a parameter the fold's half of the data hardly pins (seen taking 40-50 Jacobians
#: for 2e-3 of cost) moves its predictions along the directions the data do not see
HELD_OUT_STALL = (5, 1e-3)
POLISH_NFEV = 80  # the all-data fit of a screened candidate: near convergence, so its gain is not underrated
#: ... where it stops as a held-out fit does (HELD_OUT_TOLERANCE, HELD_OUT_STALL): five steps that lower the cost by less
#: than 1e-3 of it move the gain by less than 0.05 % of the RMSE (the main job's diagnosis: the same finding, the
#: named model's values within 1e-4, 14 % less CPU). Not a switch's polish: its threshold's cost is stepwise (each
#: sample that changes side is a step), so its fit crawls to the threshold through steps that each lower the cost
#: little; stopped there, a housing thermostat's latch stayed at 26.9 degC, not 27.0, and the model at 3x the floor
SCOUT_NFEV = 25  # the fit from a neutral start before it is polished (where it beats the warm start)
CROSS_VALIDATED = 3
#: a polished fit whose in-sample RMSE is not lower by this share of MIN_GAIN_PCT is not cross-validated: the
#: held-out gain of a fit is below its in-sample gain (its folds see half the data)
IN_SAMPLE_SHARE = 0.5
MAX_VALIDATED = 6  # screened candidates polished at most per round, failed fits (on a bound) included
GLOBAL_STARTS = 2  # the refit after an acceptance: scouts from the model file's neutral start, beside the warm one
MAX_ROUNDS = 3
BEYOND_FLOOR = 3.0  # a final model this many times the measurements' noise floor has an error left no finding explains
# The flywheel's temperature at t = 0 is fitted per run: a run that starts with a launch leaves one
# noisy reading to start from, and the fit then bends parameters (and spurious extensions gain
# 5-10 %) to absorb that start error. Air and housing start from a 10 s line fit (identify.data).
FITTED_STARTS = ("T_flywheel",)


def diagnosed_spec(model: ModelDefinition, datasets: Sequence[FitData], per_group: tuple[str, ...] = ()) -> ModelSpec:
    """What diagnose fits for a model: its parameters (those in `per_group` once per run group) plus each run's
    fitted start of FITTED_STARTS channels."""
    spec = build_spec(model).split_per_group(per_group, run_groups(datasets))
    starts = [c for c in FITTED_STARTS if c in set(spec.network.initial.values())]
    return with_initial_states(spec, datasets, starts) if starts else spec


def run_groups(datasets: Sequence[FitData]) -> tuple[str, ...]:
    """The runs' groups in order of first appearance (each run its own where no `--group-by` was given)."""
    return tuple(dict.fromkeys(d.group_label for d in datasets))


def extended_spec(parent: ModelSpec, cand: Candidate, channels: dict[str, np.ndarray],
                  datasets: Sequence[FitData]) -> ModelSpec:
    """The spec of `parent` extended by `cand`: its model edit, and the parameters split per run group so far plus
    the candidate's own."""
    return diagnosed_spec(cand.build(parent.definition, channels), datasets, parent.per_group + cand.splits)


@dataclass
class HeldOut:
    """Held-out predictions of one model: each sample simulated with the parameters of the fold that did not see it."""

    datasets: Sequence[FitData]
    predictions: list[dict[str, np.ndarray]]  # per run: channel -> simulated value at the fitting step
    params: list[dict[str, float]]  # per fold

    def residuals(self) -> list[dict[str, np.ndarray]]:
        """Simulated − measured (benchlab.identify.metrics.residual) per run and channel; NaN where no valid target."""
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
    alternatives: list["Alternative"] = field(default_factory=list)  # not significantly worse than this one
    at_bound: tuple[str, ...] = ()  # parameters of the refit with this extension left on a bound (a failed fit)
    run_gain_pct: float | None = None  # leave-one-run-out gain when it was named (several runs only)
    round: int = 0  # the greedy round that named it (1: the largest error the baseline had; findings list by gain)
    #: the model without this extension fitted on all diagnosed runs (spec, values): `before` on unseen runs
    parent: tuple[ModelSpec, dict[str, float]] | None = None
    unseen_before: "HeldOut | None" = None  # the parent simulated on the unseen runs (--validate)
    unseen_after: "HeldOut | None" = None  # the model with it simulated on the unseen runs
    not_identified: dict[str, str] = field(default_factory=dict)  # its added parameters the runs do not pin down, why

    @property
    def gain_pct(self) -> float:
        return gain_pct(self.before, self.after)

    @property
    def unseen_gain_pct(self) -> float | None:
        """RMSE gain on runs no fit saw (None without unseen runs, or for a split per run group, which an unseen run
        has no value of)."""
        return None if self.unseen_after is None else gain_pct(self.unseen_before, self.unseen_after)

    @property
    def unseen_p_value(self) -> float | None:
        """The block test of the gain on the unseen runs (the in-run test, on their blocks)."""
        return None if self.unseen_after is None else block_test(self.unseen_before, self.unseen_after)

    @property
    def lead_reasons(self) -> list[str]:
        """Why the extension is a lead and not a cause: added parameters the runs do not identify, a gain that does
        not carry to the unseen runs (the in-run acceptance rule applied to them). Empty for a cause."""
        reasons = [f"{name} not identified: {why}" for name, why in self.not_identified.items()]
        if self.unseen_after is not None and not significant(self.unseen_gain_pct, self.unseen_p_value):
            reasons.append(f"its gain does not carry to the unseen runs: {self.unseen_gain_pct:.1f} % "
                           f"(p = {self.unseen_p_value:.2g}; a cause needs >= {MIN_GAIN_PCT:g} % at p < {ALPHA:g})")
        return reasons

    @property
    def significant(self) -> bool:
        """Held-out gain of at least MIN_GAIN_PCT, and "no gain" rejected at ALPHA."""
        return significant(self.gain_pct, self.p_value)


def significant(gain: float, p_value: float) -> bool:
    """The acceptance rule, in-run and on unseen runs: a gain of at least MIN_GAIN_PCT and "no gain" rejected at
    ALPHA by the block test."""
    return gain >= MIN_GAIN_PCT and p_value < ALPHA


def gain_pct(before: "HeldOut", after: "HeldOut") -> float:
    """How much lower the RMSE of `after` is than that of `before`, %."""
    return 100.0 * (1.0 - after.rmse / before.rmse)


@dataclass(frozen=True)
class Alternative:
    """Another extension that passed against the same parent and that the accepted one does not beat significantly."""

    candidate: Candidate
    gain_pct: float
    p_value: float  # its own block test against the parent
    p_vs_winner: float  # the block test that the accepted extension's held-out error is lower than this one's
    added: int  # the parameters it would add
    #: its model (the parent as judged, with this extension) and its fit on all the diagnosed runs, the one its
    #: held-out test started from: kept so that what would tell it apart is measured without fitting it again
    spec: ModelSpec
    params: dict[str, float]
    #: the named extension's model and fit that it was tested against (p_vs_winner), fitted alike
    named: tuple[ModelSpec, dict[str, float]]


@dataclass
class Diagnosis:
    """The baseline, the accepted findings (largest gain first) and the final model, each with held-out predictions."""

    baseline: FitResult
    baseline_held: HeldOut
    findings: list[Finding]
    final: FitResult
    final_held: HeldOut
    baseline_at_bound: list[tuple[str, str]] = field(default_factory=list)  # the baseline's parameters on a bound,
    # with the bound ("min", "max") each sits on: held there while candidates are judged (pinned)
    failed_fits: list[tuple[str, tuple[str, ...]]] = field(default_factory=list)  # candidate, parameters on a bound
    not_carried: list[tuple[str, float]] = field(default_factory=list)  # candidate, its leave-one-run-out gain (%)
    noise_floor: float = float("nan")  # K: the measurements' own noise at the fitting step (noise_floor)
    leads: list[Finding] = field(default_factory=list)  # passed in-run but not a cause (Finding.lead_reasons)
    unseen_baseline: HeldOut | None = None  # the baseline simulated on the unseen runs (--validate)
    unseen_final: HeldOut | None = None  # the final model simulated on them
    evidence: list = field(default_factory=list)  # the baseline's held-out residuals against every signal, ranked
    # (benchlab.diagnose.evidence.Evidence rows): what guides the level laws, and what the JSON shows


def noise_floor(datasets: Sequence[FitData]) -> float:
    """The RMSE a perfect model would score, K: the fitting targets' white noise (metrics.difference_noise), pooled
    over every target of every run. Measured on the simulated bench it is within 3 % of the true sensors' error."""
    pooled = [difference_noise(values) for d in datasets for values in d.targets.values()]
    count = sum(n for _, n in pooled)
    return float(np.sqrt(sum(sigma ** 2 * n for sigma, n in pooled if n) / count)) if count else float("nan")


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
        result = fit(spec, train, max_nfev=HELD_OUT_NFEV, start={p.name: start[p.name] for p in spec.free},
                     tolerance=HELD_OUT_TOLERANCE, stall=HELD_OUT_STALL)
        params.append(result.params)
        for pred, d in zip(predictions, test):
            for c, values in simulate_outputs(spec.network, result.params, d).items():
                pred[c][d.mask] = values[d.mask]
    return HeldOut(datasets, predictions, params)


def _held_out_runs(spec: ModelSpec, start: dict[str, float], datasets: Sequence[FitData]) -> HeldOut:
    """Leave-one-run-out: each run predicted by a fit (warm-started at `start`) on the other runs only, from its first
    readings (its own fitted start temperatures are not used): held out means another run, not interpolation between
    blocks of the same run."""
    predictions, params = [], []
    for i, d in enumerate(datasets):
        own = {name: start[name] for name in start if name.endswith(f"@{d.name}")}
        held = spec.with_fixed(own)
        result = fit(held, [e for j, e in enumerate(datasets) if j != i], max_nfev=HELD_OUT_NFEV,
                     start={p.name: start[p.name] for p in held.free}, tolerance=HELD_OUT_TOLERANCE,
                     stall=HELD_OUT_STALL)
        params.append(result.params)
        predictions.append(simulate_outputs(spec.network, {k: v for k, v in result.params.items() if k not in own}, d))
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


def block_test(before: HeldOut, after: HeldOut) -> float:
    """One-sided p-value that the extension does not lower the held-out error, blocks as units.

    The t-test is on each block's log ratio of mean squared errors: scale-free, so a few blocks
    where the error was large (a missed heat source after every launch) do not swamp the rest.
    """
    return block_statistic(before, after)[1]


def block_statistic(before: HeldOut, after: HeldOut) -> tuple[float, float]:
    """`block_test`'s t statistic and one-sided p-value (t 0 and p 1 below three blocks or where no block differs)."""
    _, inverse = np.unique(before.blocks, return_inverse=True)
    count = np.bincount(inverse)
    log_ratio = np.log(np.bincount(inverse, before.squared) / count) - np.log(np.bincount(inverse, after.squared) / count)
    if len(log_ratio) < 3 or np.allclose(log_ratio, 0):
        return 0.0, 1.0
    test = stats.ttest_1samp(log_ratio, 0.0, alternative="greater")
    return float(test.statistic), float(test.pvalue)


Screened = tuple[float, Candidate, ModelSpec, dict[str, float]]  # in-sample cost, candidate, its spec, fitted values


def at_bound(result: FitResult) -> tuple[str, ...]:
    """The free parameters a fit left on a bound (benchlab.identify.identifiability.on_bound): where they sit, the
    fit failed."""
    return tuple(name for name, _ in bound_sides(result))


def bound_sides(result: FitResult) -> list[tuple[str, str]]:
    """Each free parameter on a bound with the side it sits on ("min" or "max"): the bound a user would widen."""
    sides = {"lower": "min", "upper": "max"}
    return [(p.name, sides[side]) for p in result.spec.free
            if (side := on_bound(p, result.params[p.name])) is not None]


def pinned(current: FitResult, datasets: Sequence[FitData]) -> FitResult:
    """The current fit with its model's parameters that sit on a bound held there, the rest refitted from where they
    are: candidates are then judged by what they add, and only their own new parameters on a bound can fail them
    (a real model file's bounds bind, and a baseline parameter on its bound must not silence discovery)."""
    model = current.spec.definition
    held = {name: current.params[name] for name in at_bound(current) if name in model.parameters}
    if not held:
        return current
    spec = diagnosed_spec(model.with_fixed(held), datasets, current.spec.per_group)
    return fit(spec, datasets, max_nfev=HELD_OUT_NFEV, start={p.name: current.params[p.name] for p in spec.free})


def _nested_start(spec: ModelSpec, current: FitResult) -> dict[str, float]:
    """A candidate's start: the current model's fitted values, the new parameters at their no-effect values (a
    parameter split per run group at its shared value for every group)."""
    def nested(p: ParamSpec) -> float:
        shared = p.name.split("@")[0]
        return current.params.get(shared, p.initial) if shared in spec.per_group else p.initial

    return {**{p.name: nested(p) for p in spec.free}, **{k: current.params[k] for k in current.free_names}}


def _starts(cand: Candidate, spec: ModelSpec, current: FitResult) -> list[dict[str, float]]:
    """Where a candidate is screened from: its screening starts where it has them (a node of 1 J/K, a link of
    1e4 K/W or a lag of 5 ms is flat there), else its nested start."""
    nested = _nested_start(spec, current)
    return [{**nested, **probe} for probe in cand.probes(current.params)] if cand.probes else [nested]


def _score(specs: Sequence[ModelSpec], cands: Sequence[Candidate], current: FitResult,
           datasets: Sequence[FitData]) -> list[tuple[float, dict[str, float]]]:
    """Per candidate, the in-sample cost one Gauss-Newton step from its best start would reach, every parameter
    free, and that start (a switch's refined around the best of its grid: Candidate.refine).

    The current model's Jacobian is the fit's own; the new parameters' columns are forward differences at the
    start (one simulation each). At the nested start they are projected off the current columns (the current
    parameters are released with them) and only what they add beyond them counts; at a screening start, away from
    the parent, the whole step counts. Columns that vanish at the nested start (an exponent while its factor is
    zero) are skipped, and a candidate that is its parent exactly there takes the parent's residuals. A composition
    scores the better of its screening starts and its nested start: where the parent bent its parameters to absorb
    the effect, one step from a probe can rank it below the parent while the first-order gain at the nested start
    shows it (a contact that differs run by run on 20-min runs); its short fit still starts from its best probe.
    """
    jac = current.jacobian / np.maximum(np.linalg.norm(current.jacobian, axis=0), 1e-300)
    basis, _ = np.linalg.qr(jac)

    def project(v: np.ndarray) -> np.ndarray:
        return v - basis @ (basis.T @ v)

    parent = residual_vector(current.spec.network, {**current.spec.fixed, **current.params}, datasets)

    def at(spec: ModelSpec, cand: Candidate, start: dict[str, float], nested: bool) -> float:
        x0 = to_coordinates(spec, start)
        new = [j for j, p in enumerate(spec.free)
               if p.name not in current.params and not (nested and p.name in cand.inert)]
        r0 = parent if nested and cand.exact else residual_vector(spec.network, {**spec.fixed, **start}, datasets)
        columns = []
        for j in new:
            x = x0.copy()
            x[j] += SCORE_STEP
            columns.append(residual_vector(spec.network, {**spec.fixed, **from_coordinates(spec, x)}, datasets) - r0)
        rest = project(r0)
        if not columns:  # a candidate with no new parameter (a re-pointed boundary): the current ones' step counts
            return float(r0 @ r0 if nested else rest @ rest)
        a = project(np.column_stack(columns))
        step, *_ = np.linalg.lstsq(a, rest, rcond=1e-10)
        left = rest - a @ step
        return float(left @ left + (0.0 if not nested else r0 @ r0 - rest @ rest))

    def score_one(i: int) -> tuple[float, dict[str, float]]:
        spec, cand = specs[i], cands[i]
        starts, nested = _starts(cand, spec, current), cand.probes is None or cand.nested_probes
        costs = [at(spec, cand, start, nested) for start in starts]
        best = int(np.argmin(costs))
        if cand.refine is not None:  # a switch's threshold: refined around its best start (Candidate.refine)
            origin = _nested_start(spec, current)
            starts = [starts[best]] + [{**origin, **probe} for probe in cand.refine(starts[best])]
            costs = [costs[best]] + [at(spec, cand, start, nested) for start in starts[1:]]
            best = int(np.argmin(costs))
        if cand.composed and cand.probes:  # ranked by its first-order gain too, screened from its best probe
            return min(costs[best], at(spec, cand, _nested_start(spec, current), True)), starts[best]
        return costs[best], starts[best]

    return map_indices(score_one, len(specs))


def _screen(cands: Sequence[Candidate], current: FitResult, datasets: Sequence[FitData],
            channels: dict[str, np.ndarray], progress: Progress, what: str) -> list[Screened]:
    """Score every candidate, then a short in-sample fit, every parameter free, of the SCORED_FITS best-scored, the
    STRUCTURAL_FITS best-scored structural ones (extra nodes, lags: the score's first step is rougher there), the
    SWITCH_FITS best-scored switches with their simpler forms (a switch's latch) and every law of the COMPOSED_FITS
    best-scored two-step explanations (their extra parameter always scores them ahead: in slots of their own they
    leave the one-step candidates' screen as it is; every law, so that the simplest form is judged beside the
    best-scored) from the start that scored best; those that lower the current cost (a composition: below
    COMPOSED_MARGIN of the best one-step cost), by cost, best first.

    Every parameter, not only the new ones: a model that lacks an effect has bent its other
    parameters to absorb it, and the new term pays off only once they are released (a plate share
    of 0.35 screened alone lowered the cost by 0 %, with all parameters free by 40 %).
    """
    specs = [extended_spec(current.spec, cand, channels, datasets) for cand in cands]
    scores = _score(specs, cands, current, datasets)
    order = list(np.argsort([cost for cost, _ in scores]))
    one_step = [i for i in order if not cands[i].composed]
    structural = [i for i in one_step if cands[i].structural]
    switches = [i for i in one_step if cands[i].nested_probes][:SWITCH_FITS]
    index = {c.key: i for i, c in enumerate(cands)}
    switches += [index[key] for i in switches for key in cands[i].simpler if key in index]
    composed = [i for i in order if cands[i].composed]
    explanations = list(dict.fromkeys(_explains(cands[i]) for i in composed))[:COMPOSED_FITS]
    composed = [i for i in composed if _explains(cands[i]) in explanations]  # every law of each: the simplest too
    chosen = list(dict.fromkeys(one_step[:SCORED_FITS] + structural[:STRUCTURAL_FITS] + switches + composed))

    def screen_one(k: int) -> tuple[float, dict[str, float]]:
        i = chosen[k]
        start = scores[i][1]
        result = fit(specs[i], datasets, max_nfev=SCREEN_NFEV, start=start)
        return result.cost, result.params

    with progress.task(what, len(chosen), unit="fit") as task:
        screened = map_indices(screen_one, len(chosen), task.advance)
    kept = [(cost, cands[i], specs[i], params) for i, (cost, params) in zip(chosen, screened) if cost < current.cost]
    best_one_step = min((cost for cost, cand, _, _ in kept if not cand.composed), default=current.cost)
    kept = [item for item in kept if not item[1].composed or item[0] < COMPOSED_MARGIN * best_one_step]
    return sorted(kept, key=lambda item: item[0])


def _polished(spec: ModelSpec, warm: dict[str, float], current: FitResult, datasets: Sequence[FitData],
              stepwise: bool = False) -> tuple[FitResult | None, tuple[str, ...]]:
    """A candidate fitted near convergence (POLISH_NFEV; to convergence where `stepwise`: a switch's threshold) from
    its warm (screened) start, and from the model file's neutral start (the new parameters nested) scouted and
    polished where it does better, or where the warm fit failed (the candidate's own parameters on a bound) and the
    scout found another minimum; the better fit with none of the candidate's own new parameters on a bound, or None
    and those parameters. A scout that reaches the warm fit's minimum (within its standard errors, as identify's
    multistart judges two starts alike: `arrived`) stops there: going on could only find that minimum again. (A
    parameter of the model itself that ends on a bound fails no candidate: polishing the scout's minimum for it,
    which the scout's higher cost already ranks below the warm fit's, re-found the warm fit or a worse one in every
    case of the main job's diagnosis.)"""
    neutral = {**{p.name: p.initial for p in spec.free},
               **{k: v for k, v in current.params.items() if k.startswith("init_") and k in warm}}

    def own_at_bound(r: FitResult) -> tuple[str, ...]:
        return tuple(name for name in at_bound(r) if name not in current.params)

    stops = {} if stepwise else {"tolerance": HELD_OUT_TOLERANCE, "stall": HELD_OUT_STALL}
    fits = [fit(spec, datasets, max_nfev=POLISH_NFEV, start={p.name: warm[p.name] for p in spec.free}, **stops)]
    reached = arrived(fits[0])
    scout = fit(spec, datasets, max_nfev=SCOUT_NFEV, start={p.name: neutral[p.name] for p in spec.free},
                stop=reached)
    elsewhere = reached is None or not reached(scout.params)
    if scout.cost < fits[0].cost or (own_at_bound(fits[0]) and elsewhere):
        fits.append(fit(spec, datasets, max_nfev=POLISH_NFEV, start={p.name: scout.params[p.name] for p in spec.free},
                        **stops))
    good = [r for r in fits if not own_at_bound(r)]
    if good:
        return min(good, key=lambda r: r.cost), ()
    return None, own_at_bound(min(fits, key=lambda r: r.cost))


@dataclass
class Tried:
    """A cross-validated candidate: its fit (values, in-sample cost and residuals), held-out predictions and block
    test against the current model."""

    candidate: Candidate
    spec: ModelSpec
    params: dict[str, float]
    cost: float
    residuals: np.ndarray
    held: HeldOut
    p_value: float
    gain_pct: float


def _try(scored: Sequence[Screened], current: FitResult, current_held: HeldOut, datasets: Sequence[FitData],
         failed: list[tuple[str, tuple[str, ...]]], pool: Sequence[Candidate] = (),
         channels: dict[str, np.ndarray] | None = None,
         not_carried: list[tuple[str, float]] | None = None) -> Finding | None:
    """Polish and cross-validate the best-screened candidates, down the list past failed fits until CROSS_VALIDATED
    explanations have a good fit (laws of one explanation count once: they are not alternatives to each other; at
    most MAX_VALIDATED tried). Of the significant ones, the simplest that the largest gain does
    not beat at ALPHA is the finding (_simplest_equal), with the others that are not significantly worse as its
    alternatives. Where the largest gain reads several signals, its simpler forms in `pool` (the same mechanism at
    the same nodes on fewer of them) are validated too: a product is named only where the data ask for it. Every
    other screened candidate no more complex than the one about to be named is validated before it is named, so the
    rule applies over the whole screened list, not over the few that the screen's rough ranking happened to put
    first. With several runs the named one must also carry to runs it was not fitted on (leave-one-run-out RMSE
    MIN_GAIN_PCT below the current model's); one that does not is appended to `not_carried` with that gain and the
    next is named. A parameter split per run group is exempt: it says the runs differ, so a run it was not fitted
    on cannot have its value; its held-out test is on the blocks of each run that its fit did not see.
    Failed fits are appended to `failed`."""
    tried: list[Tried] = []
    seen: set[str] = set()
    explained: set[tuple] = set()  # the explanations (_explains) with a good fit

    def run(batch: Sequence[Screened]) -> None:
        """Polish and cross-validate `batch` (on all cores) and record each."""
        def validate(i: int) -> tuple:  # plain values: a worker's result is pickled, the networks' laws cannot be
            _, cand, spec, params = batch[i]
            result, bound = _polished(spec, params, current, datasets, cand.nested_probes)
            if result is None:
                return None, bound
            if 100.0 * (1.0 - np.sqrt(result.cost / current.cost)) < IN_SAMPLE_SHARE * MIN_GAIN_PCT:
                return (), ()  # cannot gain MIN_GAIN_PCT held out: not cross-validated
            held = _held_out(spec, result.params, datasets)
            return (result.params, result.cost, result.residuals, held.predictions, held.params), bound

        for (_, cand, spec, _), (values, bound) in zip(batch, map_indices(validate, len(batch))):
            seen.add(cand.key)
            if values is None:
                failed.append((cand.key, bound))
                continue
            explained.add(_explains(cand))
            if values:
                params, cost, residuals, predictions, fold_params = values
                held = HeldOut(datasets, predictions, fold_params)
                tried.append(Tried(cand, spec, params, cost, residuals, held, block_test(current_held, held),
                                   gain_pct(current_held, held)))

    offered = list(scored[:MAX_VALIDATED])
    while offered and len(explained) < CROSS_VALIDATED:
        batch, offered = offered[:CROSS_VALIDATED - len(explained)], offered[CROSS_VALIDATED - len(explained):]
        run(batch)
    named = _named(tried, current)
    if named is None:
        return None
    best = max(_passing(tried), key=lambda t: t.gain_pct)
    simpler = [c for c in pool if c.mechanism == best.candidate.mechanism and c.nodes == best.candidate.nodes
               and set(c.reads) < set(best.candidate.reads) and c.key not in seen]
    if simpler and channels is not None:
        run([(0.0, c, spec, _nested_start(spec, current))
             for c in simpler for spec in [extended_spec(current.spec, c, channels, datasets)]])
    while True:
        named = _named(tried, current)
        unseen = [s for s in scored if s[1].key not in seen
                  and _explains(s[1]) != _explains(named.candidate)
                  and _spec_complexity(s[2], s[1], current) <= _complexity(named, current)]
        if not unseen:
            break
        run(unseen)
    run_gain = None
    if len(datasets) > 1:
        parent_runs = _held_out_runs(current.spec, current.params, datasets).rmse
        while named is not None and not named.candidate.splits:
            run_gain = 100.0 * (1.0 - _held_out_runs(named.spec, named.params, datasets).rmse / parent_runs)
            if run_gain >= MIN_GAIN_PCT:
                break
            if not_carried is not None:
                not_carried.append((named.candidate.key, run_gain))
            tried = [t for t in tried if _explains(t.candidate) != _explains(named.candidate)]
            named = _named(tried, current)
        if named is None:
            return None
    alternatives = [Alternative(t.candidate, t.gain_pct, t.p_value, block_test(t.held, named.held),
                                len(_added(t.spec, current)), t.spec, t.params, (named.spec, named.params))
                    for t in _passing(tried) if _explains(t.candidate) != _explains(named.candidate)]
    return _finding(named.candidate, named.spec, named.params, named.cost, named.residuals, current, current_held,
                    named.held, [a for a in alternatives if a.p_vs_winner >= ALPHA], run_gain)


def _passing(tried: Sequence[Tried]) -> list[Tried]:
    """The cross-validated extensions that pass: held-out gain of at least MIN_GAIN_PCT, "no gain" rejected at ALPHA."""
    return [t for t in tried if t.gain_pct >= MIN_GAIN_PCT and t.p_value < ALPHA]


def _named(tried: Sequence[Tried], current: FitResult) -> Tried | None:
    """The extension a finding names among those cross-validated: the simplest passing one that the largest gain does
    not beat (_simplest_equal); None where none passes."""
    passing = _passing(tried)
    if not passing:
        return None
    return _simplest_equal(max(passing, key=lambda t: t.gain_pct), passing, current)


def _complexity(tried: Tried, current: FitResult) -> tuple[int, int]:
    """How much an extension asks of the data: the parameters it adds, then the signals it reads."""
    return _spec_complexity(tried.spec, tried.candidate, current)


def _spec_complexity(spec: ModelSpec, cand: Candidate, current: FitResult) -> tuple[int, int]:
    """_complexity of a candidate's spec before it is fitted."""
    return len(_added(spec, current)), len(cand.reads)


def _added(spec: ModelSpec, current: FitResult) -> tuple[str, ...]:
    """The free parameters of an extension's spec that the current model does not have."""
    return tuple(p.name for p in spec.free if p.name not in current.params)


def _simplest_equal(best: Tried, passing: Sequence[Tried], current: FitResult) -> Tried:
    """The simplest passing extension that `best` does not beat at ALPHA (the same block test between the two), the
    larger gain among equally simple ones: a parameter or a signal more is named only where the data ask for it.
    Only other explanations compete (_explains): among the laws of one explanation the best fitting one is kept."""
    equal = [t for t in passing if t is best or (_explains(t.candidate) != _explains(best.candidate)
                                                 and block_test(t.held, best.held) >= ALPHA)]
    return min(equal, key=lambda t: (_complexity(t, current), -t.gain_pct))


def _explains(cand: Candidate) -> tuple:
    """What a finding tells the user: signal, mechanism and the nodes it acts on; candidates alike in these are
    forms of one explanation, not alternatives to it."""
    return frozenset(cand.reads), cand.mechanism, frozenset(cand.nodes), cand.splits


def _finding(cand: Candidate, spec: ModelSpec, params: dict[str, float], cost: float, residuals: np.ndarray,
             current: FitResult, current_held: HeldOut, held: HeldOut, alternatives: list["Alternative"],
             run_gain_pct: float | None = None) -> Finding:
    """The finding of an extension fitted to `params` (in-sample cost and residuals) on top of `current`."""
    added = _added(spec, current)
    return Finding(cand, spec, params, added, current_held, held, block_test(current_held, held),
                   _bic_delta(current.cost, cost, residuals, len(added)), alternatives, run_gain_pct=run_gain_pct)


def global_fit(spec: ModelSpec, warm: dict[str, float], datasets: Sequence[FitData], seed: int) -> FitResult:
    """The whole model refitted after an acceptance: from the warm start, and a multistart from the model file's
    neutral start (spread scouts, the best polished); the better fit with no parameter on a bound, else the
    better one, whose bound parameters the finding reports."""
    warm_fit = fit(spec, datasets, start={p.name: warm[p.name] for p in spec.free})
    neutral = fit_multistart(spec, datasets, starts=GLOBAL_STARTS, seed=seed)
    fits = [warm_fit, neutral]
    good = [r for r in fits if not at_bound(r)]
    return min(good or fits, key=lambda r: r.cost)


def refit_candidate(cand: Candidate, current: FitResult, datasets: Sequence[FitData], channels: dict[str, np.ndarray],
                    seed: int) -> FitResult:
    """`cand` added to `current` and fitted as a diagnosis fits the finding it accepts: screened from its best start
    (`_screen`: a probe where its new parameters are flat at the nested start), polished with a scout from the model
    file's neutral start (`_polished`), then refitted whole (`global_fit`). Where the screen cannot lower the
    current cost or the polish leaves its own parameters on a bound, the whole refit starts from the best so far."""
    judged = pinned(current, datasets)
    spec = extended_spec(current.spec, cand, channels, datasets)
    screened = _screen([cand], judged, datasets, channels, SILENT, f"refit {cand.key}")
    warm = {**current.params, **(screened[0][3] if screened else _nested_start(spec, judged))}
    polished, _ = _polished(extended_spec(judged.spec, cand, channels, datasets), warm, judged, datasets,
                            cand.nested_probes)
    return global_fit(spec, {**warm, **(polished.params if polished else {})}, datasets, seed)


def _combined(base: ModelSpec, cands: Sequence[Candidate], channels: dict[str, np.ndarray],
              datasets: Sequence[FitData]) -> ModelSpec:
    """The baseline with the given extensions applied in order."""
    spec = base
    for cand in cands:
        spec = extended_spec(spec, cand, channels, datasets)
    return spec


def _recheck(base: FitResult, base_held: HeldOut, findings: Sequence[Finding], final: FitResult,
             final_held: HeldOut, datasets: Sequence[FitData], channels: dict[str, np.ndarray]) -> list[Finding]:
    """Each accepted extension measured against the final model without it (drop-one, held out).

    The greedy steps measured each gain on top of the ones found before it; with several findings
    the fair figure is what the combined model loses without it.
    """
    def spec_without(i: int) -> ModelSpec:
        others = [g.candidate for g in findings if g is not findings[i]]
        return _combined(base.spec, others, channels, datasets) if others else base.spec

    def without(i: int) -> tuple[float, HeldOut, dict[str, float]]:  # plain values: a worker's result is pickled
        if len(findings) == 1:
            return base.cost, base_held, base.params
        spec = spec_without(i)
        refit = fit(spec, datasets, max_nfev=HELD_OUT_NFEV, start={p.name: final.params[p.name] for p in spec.free})
        return refit.cost, _held_out(spec, refit.params, datasets), refit.params

    return [Finding(f.candidate, final.spec, final.params, f.added, held, final_held, block_test(held, final_held),
                    _bic_delta(cost, final.cost, final.residuals, len(f.added)), f.alternatives, f.at_bound,
                    f.run_gain_pct, f.round, parent=(spec_without(i), params))
            for i, (f, (cost, held, params)) in enumerate(zip(findings, map_indices(without, len(findings))))]


def _accept(findings: list[Finding], current: FitResult, current_held: HeldOut, base: FitResult, base_held: HeldOut,
            datasets: Sequence[FitData], channels: dict[str, np.ndarray]) -> tuple[list[Finding], FitResult, HeldOut]:
    """Drop-one re-check until every remaining finding passes against the rest (gain and alpha, as documented)."""
    while findings:
        if len(findings) > 1:
            findings = _recheck(base, base_held, findings, current, current_held, datasets, channels)
        kept = [f for f in findings if f.significant]
        if len(kept) == len(findings):
            return findings, current, current_held
        if not kept:
            return [], base, base_held
        spec = _combined(base.spec, [f.candidate for f in kept], channels, datasets)
        current = fit(spec, datasets, start={p.name: current.params[p.name] for p in spec.free})
        current_held = _held_out(spec, current.params, datasets)
        findings = _recheck(base, base_held, kept, current, current_held, datasets, channels)
    return [], base, base_held


def on_unseen(spec: ModelSpec, params: dict[str, float], unseen: Sequence[FitData]) -> HeldOut | None:
    """A model fitted on the diagnosed runs simulated on runs none of its fits saw, each from its own first readings
    (the diagnosed runs' fitted start temperatures are theirs); None for a model with a parameter split per run
    group, which an unseen run has no value of."""
    if not unseen or spec.per_group:
        return None
    shared = {name: value for name, value in params.items() if "@" not in name}
    return HeldOut(unseen, [simulate_outputs(spec.network, shared, d) for d in unseen], [shared])


def _judge(findings: Sequence[Finding], final: FitResult, datasets: Sequence[FitData],
           unseen: Sequence[FitData]) -> None:
    """Each finding's identifiability in the final fit (its added parameters, by the residuals' sandwich standard
    errors, benchlab.identify.identifiability) and its parent and final model on the unseen runs."""
    errors = estimate_uncertainty(final, datasets, [{} for _ in datasets]).standard_errors
    for f in findings:
        f.not_identified = not_identified([p for p in final.spec.free if p.name in f.added], final.params, errors)
        if f.parent is not None and not f.candidate.splits:
            f.unseen_before, f.unseen_after = on_unseen(*f.parent, unseen), on_unseen(final.spec, final.params, unseen)


def _worst_lead(findings: Sequence[Finding]) -> Finding | None:
    """The finding to take out first: one with a parameter not identified, else the lowest unseen gain of those whose
    gain does not carry; None where every finding is a cause."""
    leads = [f for f in findings if f.lead_reasons]
    if not leads:
        return None
    return min(leads, key=lambda f: (not f.not_identified, f.unseen_gain_pct if f.unseen_gain_pct is not None else 0.0))


def _simpler_form(lead: Finding, kept: Sequence[Finding], current: FitResult, base: FitResult,
                  datasets: Sequence[FitData], channels: dict[str, np.ndarray],
                  forms: Sequence[Candidate]) -> Finding | None:
    """For a lead whose added parameters are not all identified, the best-fitting of its simpler forms in `forms` (the
    same mechanism on a subset of its nodes, reading no more signals: a node bridging P and F whose link to P the runs
    cannot pin is a mass hung on F; and those it names, `Candidate.simpler`: a switch whose band the runs never
    exercise is a latch) fitted beside the findings `kept`, with none of its own parameters on a bound; None
    where it has none. Its held-out figures are measured by the drop-one re-check (_recheck) that follows."""
    cands = [c for c in forms if c.key in lead.candidate.simpler or (
        c.mechanism == lead.candidate.mechanism and set(c.nodes) < set(lead.candidate.nodes)
        and set(c.reads) <= set(lead.candidate.reads))]
    parent = _combined(base.spec, [f.candidate for f in kept], channels, datasets)
    fitted = []
    for cand in cands:
        spec = extended_spec(parent, cand, channels, datasets)
        starts = _starts(cand, spec, current)
        if cand.key in lead.candidate.simpler:  # where the lead's fit put what they share
            names = {p.name for p in spec.free}
            starts.append({**_nested_start(spec, current), **{k: v for k, v in carried_values(
                lead.candidate, cand, current.params).items() if k in names}})
        screened = min((fit(spec, datasets, max_nfev=SCREEN_NFEV, start=start) for start in starts),
                       key=lambda r: r.cost)
        result, _ = _polished(spec, screened.params, current, datasets, cand.nested_probes)
        if result is not None:
            fitted.append((result, cand, spec))
    if not fitted:
        return None
    result, cand, spec = min(fitted, key=lambda item: item[0].cost)
    added = tuple(p.name for p in spec.free if p.name not in {q.name for q in parent.free})
    return Finding(cand, spec, result.params, added, lead.before, lead.after, 1.0, 0.0, round=lead.round)


def _causes(findings: list[Finding], current: FitResult, current_held: HeldOut, base: FitResult, base_held: HeldOut,
            datasets: Sequence[FitData], channels: dict[str, np.ndarray], unseen: Sequence[FitData],
            forms: Sequence[Candidate] = ()) -> tuple[list[Finding], list[Finding], FitResult, HeldOut]:
    """The accepted findings split into causes and leads (Finding.lead_reasons), one lead at a time (_worst_lead: the
    findings were measured together, and a spurious one can drag another's unseen gain down): it is taken out (a lead
    for parameters not identified replaced by its simpler form among `forms`, _simpler_form, once), the rest refitted
    together, re-checked drop-one (_accept) and judged again, until every one left is a cause."""
    leads: list[Finding] = []
    tried = {f.candidate.key for f in findings}
    while findings:
        _judge(findings, current, datasets, unseen)
        worst = _worst_lead(findings)
        if worst is None:
            return findings, leads, current, current_held
        leads.append(worst)
        kept = [f for f in findings if f is not worst]
        if worst.not_identified:
            simpler = _simpler_form(worst, kept, current, base, datasets, channels,
                                    [c for c in forms if c.key not in tried])
            if simpler is not None:
                tried.add(simpler.candidate.key)
                kept.append(simpler)
        if not kept:
            break
        spec = _combined(base.spec, [f.candidate for f in kept], channels, datasets)
        values = {**{k: v for f in kept for k, v in f.params.items()}, **current.params}  # a simpler form's own too
        current = fit(spec, datasets, start={p.name: values[p.name] for p in spec.free})
        current_held = _held_out(spec, current.params, datasets)
        findings, current, current_held = _accept(
            _recheck(base, base_held, kept, current, current_held, datasets, channels), current, current_held, base,
            base_held, datasets, channels)
    return [], leads, base, base_held


def baseline_evidence(base: FitResult, base_held: HeldOut) -> list:
    """The baseline's held-out residuals tested against every signal and model state, ranked (benchlab.diagnose.
    evidence; computed once, here, for the library and the JSON)."""
    from benchlab.diagnose.evidence import residual_evidence  # it reads the engine's constants

    return residual_evidence(base_held, base.spec, base.params)


def level_channels(datasets: Sequence[FitData], measured: Sequence[str], evidence: Sequence = ()) -> tuple[str, ...]:
    """Every temperature of the runs that the evidence tests (the measured outputs and the channels the model reads,
    `evidence.tested_signals`; an unmeasured node's level is no law's to read), in the order of `evidence` where
    given (a model state named by the channel that measures it: `model T_air` is T_air): a residual that follows a
    temperature's own level points to a law of that level (a thermostat's fan). All of them, not the first few by
    rank: every temperature rises and falls with the runs' heat, so their level rows explain the residual alike
    (50-77 % each on a housing thermostat's fan) and their order is noise; a thermostat's own temperature ranked
    third there and its law was never tried. Each adds about six candidates. Without evidence (`benchlab design`
    rebuilding a diagnosis' rivals) the same temperatures, so every key diagnose can name is rebuilt."""
    from benchlab.diagnose.evidence import tested_signals  # it reads the engine's constants

    temperatures = [name for name, _, unit in tested_signals(datasets, measured) if unit == "degC"]
    ranked = [e.signal.removeprefix("model ") for e in evidence if e.unit == "degC"]
    return tuple(dict.fromkeys([name for name in ranked if name in temperatures] + temperatures))


def library_for(model: ModelDefinition, channels: dict[str, np.ndarray], units: dict[str, str],
                datasets: Sequence[FitData], group_by: str | None = None,
                levels: Sequence[str] = ()) -> list[Candidate]:
    """Every candidate diagnose tries on these runs: the model's library (with the level laws of `levels`, the
    runs' temperatures: `level_channels`), its two-step link compositions and, with several run groups,
    each parameter split per group."""
    groups = run_groups(datasets)
    library = candidates(model, channels, units, levels) + composed_links(model, channels, units, groups)
    if len(groups) > 1:
        library += per_group_candidates(model, [p.name for p in model.free_parameters()], group_by or "run")
    return library


@single_threaded_blas
def diagnose_runs(runs: Sequence[pd.DataFrame], baseline: "str | ModelDefinition" = "linear", starts: int = 4,
                  seed: int = 0, progress: Progress = SILENT, group_by: str | None = None,
                  validate: Sequence[pd.DataFrame] = ()) -> Diagnosis:
    """Baseline fit, greedy accepted extensions with a global refit after each, then a drop-one re-check of each
    against the combination.

    `baseline`: a built-in name, a model file or a checked model; every extension is an edit of it.
    `progress` gets a task for the baseline's multistart and one per screening of candidates. `group_by`: the run
    attribute (`bench`, `batch`, ...) whose values group the runs for "the runs disagree on a parameter"; each run is
    its own group where it is None. With one group there is no such candidate. `validate`: runs no fit sees; each
    finding's model and its parent are simulated on them (Finding.unseen_gain_pct), and a finding whose gain does
    not carry to them is a lead, as is one whose added parameters the runs do not identify (Diagnosis.leads).
    """
    duration = sum(float(run["time"].iloc[-1] - run["time"].iloc[0]) for run in runs)
    if duration < MIN_DURATION_S:
        raise ValueError(f"diagnose needs at least {MIN_DURATION_S:.0f} s of runs for held-out scoring, "
                         f"got {duration:.0f} s")
    model = baseline if isinstance(baseline, ModelDefinition) else resolve_model(baseline)
    network = build_spec(model).network
    datasets = [replace(prepare(run, STEP_S, name=str(i), network=network),
                        group=str(run.attrs[group_by]) if group_by else "") for i, run in enumerate(runs)]
    shared = set.intersection(*(set(d.channels) for d in datasets))
    channels = {k: np.concatenate([d.channels[k] for d in datasets]) for k in datasets[0].channels if k in shared}
    unseen = [prepare(run, STEP_S, name=f"unseen{i}", network=network) for i, run in enumerate(validate)]
    units = {**ALIGNED_UNITS, **runs[0].attrs.get("units", {})}
    with progress.task(f"diagnose: {model.label} baseline", starts + 1, unit="fit") as task:
        base = fit_multistart(diagnosed_spec(model, datasets), datasets, starts=starts, seed=seed, task=task)
    base_held = _held_out(base.spec, base.params, datasets)
    evidence = baseline_evidence(base, base_held)
    library = library_for(model, channels, units, datasets, group_by,
                          level_channels(datasets, network.measured, evidence))
    current, current_held, findings, failed, not_carried = base, base_held, [], [], []
    for round_ in range(1, MAX_ROUNDS + 1):
        used = {f.candidate.key for f in findings}
        finding, judged = None, pinned(current, datasets)
        remaining = [c for c in library if c.key not in used and applies(c, current.spec.definition)
                     and (c.composed or set(c.splits) <= set(judged.free_names))]
        for physical, what in ((True, "mechanisms"), (False, "learned flows")):
            if finding is None:
                pool = [c for c in remaining if c.physical == physical]
                finding = _try(_screen(pool, judged, datasets, channels, progress,
                                       f"diagnose round {round_}: {what}"), judged, current_held, datasets, failed,
                               pool, channels, not_carried)
        if finding is None:
            break
        released = extended_spec(current.spec, finding.candidate, channels, datasets)
        parent, current = current, global_fit(released, finding.params, datasets, seed + round_)
        held = _held_out(current.spec, current.params, datasets)
        finding = _finding(finding.candidate, current.spec, current.params, current.cost, current.residuals, parent,
                           current_held, held, finding.alternatives, finding.run_gain_pct)
        finding.at_bound, finding.round, finding.parent = at_bound(current), round_, (parent.spec, parent.params)
        findings.append(finding)
        current_held = held
    findings, current, current_held = _accept(findings, current, current_held, base, base_held, datasets, channels)
    findings, leads, current, current_held = _causes(findings, current, current_held, base, base_held, datasets,
                                                     channels, unseen, library)
    return Diagnosis(base, base_held, sorted(findings, key=lambda f: -f.gain_pct), current, current_held,
                     baseline_at_bound=bound_sides(base), failed_fits=failed, noise_floor=noise_floor(datasets),
                     not_carried=not_carried, leads=leads, unseen_baseline=on_unseen(base.spec, base.params, unseen),
                     unseen_final=on_unseen(current.spec, current.params, unseen), evidence=evidence)
