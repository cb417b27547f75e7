"""Discrimination: the blocks that most separate two competing models (diagnose's tied alternatives, or a cause
against the model without it), each refitted to the runs so far.

T-optimal with the refit (Atkinson and Fedorov): the criterion is the sum of squared differences of the measured
channels, each weighted by its noise, that one model refitted (linearised, held by the runs so far) cannot absorb of
the other's predictions of the designed run, the smaller of the two directions (`Misfit`). Greedy like the
precision design (`benchlab.design.precision`): the block that adds most of it per second of bench time first, each
block predicted from a bench at rest. The difference at present values (`noncentrality`) is still reported: it
counts what a refit absorbs. The expected outcome
is a forecast of the verdict (`forecast`): the chosen plan simulated whole by the favoured model with the runs'
misfit as noise, the other model refitted with that run (it absorbs what it can of the difference, as it will
after the real run), both scored by diagnose's block test.

The noise a difference is weighed against is each channel's misfit of the better model on the runs so far (its
in-sample residual RMS), not the sensors' white noise: what the models cannot explain of the runs they were fitted
to counts as noise for telling them apart. That misfit is far from white at diagnose's 1 s step, so the statistic
counts effective samples, n (1 − ρ) / (1 + ρ) with ρ the residuals' lag-1 autocorrelation (as diagnose's BIC does).
Everything is at diagnose's step (`engine.STEP_S`), so the statistic of the designed run and of the runs so far
are on one scale.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy import stats

from benchlab.design import fisher
from benchlab.design.blocks import Block, candidate_blocks, numbered
from benchlab.design.precision import too_hot
from benchlab.diagnose.engine import ALPHA  # the level the loser must be beaten at: diagnose's
from benchlab.diagnose.engine import (BEYOND_FLOOR, BLOCK_S, STEP_S, HeldOut, block_statistic, diagnosed_spec,
                                      noise_floor)
from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import fit, residual_vector, simulate_outputs
from benchlab.identify.spec import ModelSpec
from benchlab.network import ThermalNetwork
from protocols.limits import BenchLimits
from protocols.schedule import Step


@dataclass(frozen=True)
class Rival:
    """One competing model: its name (diagnose's candidate key, or the model's), spec as diagnose fits it to the
    runs so far, and refitted values."""

    name: str
    spec: ModelSpec
    params: Mapping[str, float]
    rmse: Mapping[str, float]  # each measured channel's in-sample residual RMS on the runs so far, K
    rho: float  # lag-1 autocorrelation of those residuals, pooled over channels and runs (0 to 0.99)

    @property
    def network(self) -> ThermalNetwork:
        return self.spec.network


def misfit(network: ThermalNetwork, params: Mapping[str, float], runs: Sequence[FitData]) -> tuple[dict[str, float],
                                                                                                      float]:
    """Each measured channel's residual RMS of the model on `runs` (K), pooled over the runs, and the residuals'
    lag-1 autocorrelation (the median over channels and runs, clipped to 0–0.99)."""
    pooled: dict[str, list[np.ndarray]] = {}
    rhos = []
    for data in runs:
        for channel, simulated in simulate_outputs(network, params, data).items():
            r = data.targets[channel] - simulated
            r = r[np.isfinite(r)]
            pooled.setdefault(channel, []).append(r)
            if len(r) > 2:
                rhos.append(float(np.corrcoef(r[:-1], r[1:])[0, 1]))
    rho = float(np.clip(np.median(rhos), 0.0, 0.99)) if rhos else 0.0
    return {c: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for c, v in pooled.items()}, rho


def predicted(rival: Rival, steps: Sequence[Step], ambient_c: float, limits: BenchLimits) -> FitData:
    """`rival`'s prediction of `steps` on this bench at diagnose's step."""
    run = fisher.predicted_run(steps, rival.params, rival.network, ambient_c, limits.drivetrain)
    return prepare(run, STEP_S, name="design", network=rival.network)


def predicted_run_both(first: Rival, second: Rival, steps: Sequence[Step], ambient_c: float,
                       limits: BenchLimits) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Both rivals' predicted runs of `steps` (every output, measured or not) on the prediction grid."""
    return (fisher.predicted_run(steps, first.params, first.network, ambient_c, limits.drivetrain),
            fisher.predicted_run(steps, second.params, second.network, ambient_c, limits.drivetrain))


def differences(first: Rival, second: Rival, steps: Sequence[Step], ambient_c: float,
                limits: BenchLimits) -> dict[str, np.ndarray]:
    """The two models' predictions of `steps` on this bench, first minus second, for each channel both measure."""
    a, b = predicted(first, steps, ambient_c, limits), predicted(second, steps, ambient_c, limits)
    return {c: a.targets[c] - b.targets[c] for c in a.targets if c in b.targets}


def correlated_noise(n: int, sigma: float, rho: float, rng: np.random.Generator) -> np.ndarray:
    """n samples of a stationary AR(1) process with standard deviation `sigma` and lag-1 autocorrelation `rho`: a
    misfit like the runs' at diagnose's step (slow, not white)."""
    from scipy import signal  # here, not at the top: 0.5-0.8 s of import that diagnose's sensor ranking, which
    # reads this module, does not need

    shocks = rng.standard_normal(n) * sigma * np.sqrt(1.0 - rho ** 2)
    shocks[0] = rng.standard_normal() * sigma
    return signal.lfilter([1.0], [1.0, -rho], shocks)


@dataclass(frozen=True)
class Forecast:
    """The designed run as the favoured model would deliver it, scored as the benchmark and diagnose score it."""

    rmse_gap: float  # K: the other's RMSE on the run minus the favoured's, the other refitted with the run
    block_t: float  # diagnose's block test "the other is not worse" on the run (`engine.block_statistic`)
    block_p: float
    blocks: int


def forecast(favoured: Rival, other: Rival, steps: Sequence[Step], runs: Sequence[FitData], ambient_c: float,
             limits: BenchLimits, seed: int = 0) -> Forecast:
    """T-optimal forecast of the verdict, favoured taken as the plant: the run `steps` simulated by the favoured
    model with its misfit on the runs so far added as noise (`correlated_noise`, each channel at its RMS, the
    residuals' lag-1 autocorrelation), the other refitted to the runs and that run from its values (one local fit:
    what it can absorb of the difference), both scored on the run by diagnose's block test."""
    truth = predicted(favoured, steps, ambient_c, limits)
    rng = np.random.default_rng(seed)
    run = replace(truth, name="forecast", targets={
        c: t + correlated_noise(len(t), favoured.rmse[c], favoured.rho, rng) for c, t in truth.targets.items()
        if c in favoured.rmse})
    data = [*runs, run]
    spec = diagnosed_spec(other.spec.definition, data, other.spec.per_group)
    refit = fit(spec, data, start={p.name: other.params.get(p.name, p.initial) for p in spec.free})
    held = [HeldOut([run], [simulate_outputs(network, params, run)], [])
            for network, params in ((refit.spec.network, refit.params), (favoured.network, favoured.params))]
    t, p = block_statistic(*held)
    return Forecast(held[0].rmse - held[1].rmse, t, p, len(np.unique(held[0].blocks)))


@dataclass(frozen=True)
class Misfit:
    """What one rival, refitted, cannot absorb of the other's predictions, to first order: on each block its
    residuals against the other's prediction and their Jacobian in ln|θ| (both weighted by the noise), and the
    information of the runs so far, which holds its parameters where those runs put them."""

    residuals: list[np.ndarray]  # per block
    jacobians: list[np.ndarray]  # per block
    held: np.ndarray  # information of the runs so far (ridge included)

    def left(self, chosen: Sequence[int]) -> float:
        """Σ r² left after the rival's best linearised refit to the runs so far and the `chosen` blocks (a block
        chosen twice counts twice): D − gᵀ H⁻¹ g, the T-criterion with the refit (Atkinson and Fedorov)."""
        if not chosen:
            return 0.0
        g = sum(self.jacobians[i].T @ self.residuals[i] for i in chosen)
        h = self.held + sum(self.jacobians[i].T @ self.jacobians[i] for i in chosen)
        return float(sum(self.residuals[i] @ self.residuals[i] for i in chosen) - g @ np.linalg.solve(h, g))


def refit_misfit(fitted: Rival, truth: Rival, blocks: Sequence[Block], runs: Sequence[FitData],
                 noise: Mapping[str, float], ambient_c: float, limits: BenchLimits) -> Misfit:
    """`Misfit` of `fitted` when `truth` is the plant, on each block and with the runs so far
    (`fisher.information` at its fitted values, every free parameter)."""
    names = [p.name for p in fitted.spec.free]
    params = {**fitted.spec.fixed, **fitted.params}
    held = fisher.information(fitted.network, params, names, runs, noise) + fisher.RIDGE * np.eye(len(names))
    residuals, jacobians = [], []
    for block in blocks:
        run = fisher.predicted_run(block.steps, truth.params, truth.network, ambient_c, limits.drivetrain)
        data = prepare(run, STEP_S, name="design", network=fitted.network)
        w = fisher.weights(data, noise)
        residuals.append(residual_vector(fitted.network, params, [data]) * w)
        jacobians.append(fisher.jacobian(fitted.network, params, names, data) * w[:, None])
    return Misfit(residuals, jacobians, held)


def noncentrality(diff: Mapping[str, np.ndarray], noise: Mapping[str, float], rho: float) -> float:
    """T-criterion: Σ (difference / noise)² over every channel and sample, in effective samples."""
    return float(sum(np.nansum((d / noise[c]) ** 2) for c, d in diff.items() if c in noise) * (1 - rho) / (1 + rho))


@dataclass(frozen=True)
class DiscriminationDesign:
    """The chosen blocks, their schedule, and the expected outcome: how much worse the loser should fit the run."""

    blocks: tuple[Block, ...]
    steps: tuple[Step, ...]
    favoured: str  # the model taken as right (diagnose's named finding): the other should lose
    other: str
    noise: dict[str, float]
    rms_difference: dict[str, float]  # per channel, K, over the designed run
    statistic: float  # expected non-centrality (Σ (d/σ)², effective samples) of the designed run
    statistic_now: float  # the same on the runs so far (how far they tell the two apart)
    expected: Forecast  # the verdict forecast with the favoured as the plant (`forecast`)
    floor_ratio: float  # the favoured model's RMSE on the runs so far over their noise floor (`engine.noise_floor`)

    @property
    def neither(self) -> bool:
        """The runs so far leave the favoured model beyond diagnose's limit of the noise floor: the plant may be
        neither model, and then the run may beat either (the forecast assumes the favoured is right)."""
        return self.floor_ratio > BEYOND_FLOOR

    @property
    def p_value(self) -> float:
        """The test between the two at the expected statistic (chi-square, one degree of freedom)."""
        return float(stats.chi2.sf(self.statistic, 1))

    def lines(self) -> list[str]:
        """The expected outcome, for the terminal before the run."""
        e = self.expected
        verdict = "should be beaten" if e.block_p < ALPHA else "may not be beaten"
        return [f"designed run: {len(self.blocks)} blocks, {sum(s.expected_s for s in self.steps) / 60:.1f} min",
                *(f"  block {i}: {b.name}" for i, b in enumerate(self.blocks)),
                f"to tell apart {self.favoured} (taken as right) and {self.other}:",
                *(f"  {c}: the two differ by {d:.3f} K RMS on the run against a misfit of {self.noise[c]:.3f} K"
                  for c, d in self.rms_difference.items()),
                f"expected: {self.other} {verdict} at alpha {ALPHA:g} by diagnose's block test ({e.blocks} blocks of "
                f"{BLOCK_S:g} s: t = {e.block_t:.2f}, p = {e.block_p:.2g}), its RMSE {e.rmse_gap:.3f} K above "
                f"{self.favoured}'s, if {self.favoured} is the plant (the run simulated by it with its misfit as "
                f"noise, {self.other} refitted with that run); sample statistic {self.statistic:.1f} (runs so far "
                f"{self.statistic_now:.1f})",
                *([f"caution: {self.favoured} fits the runs so far at {self.floor_ratio:.1f}x their noise floor "
                   f"(diagnose's limit {BEYOND_FLOOR:g}x): the plant may be neither model, and then the run can "
                   f"beat either, {self.favoured} included; it settles the contest, the forecast says which way only "
                   f"if {self.favoured} is right"] if self.neither else [])]


def design_discrimination(favoured: Rival, other: Rival, runs: Sequence[FitData], limits: BenchLimits,
                          ambient_c: float, budget_s: float) -> DiscriminationDesign:
    """Greedy T-optimal blocks within `budget_s`, `runs` the runs so far at diagnose's step (those the rivals were
    fitted to) (the most non-centrality per second of bench time first), the plan
    dropped from its end until it stays clear of the over-temperature interlocks under both models. ValueError
    when no block fits the budget or the interlocks."""
    blocks = [b for b in candidate_blocks(limits) if b.expected_s <= budget_s]
    if not blocks:
        raise ValueError("no block fits")
    noise = {c: min(favoured.rmse[c], other.rmse.get(c, np.inf)) for c in favoured.rmse}
    rho = min(favoured.rho, other.rho)
    now = sum(noncentrality({c: simulate_outputs(favoured.network, favoured.params, d)[c]
                             - simulate_outputs(other.network, other.params, d)[c] for c in d.targets}, noise, rho)
              for d in runs)
    misfits = [refit_misfit(a, b, blocks, runs, noise, ambient_c, limits) for a, b in ((other, favoured),
                                                                                         (favoured, other))]

    def separation(chosen: Sequence[int]) -> float:  # whichever is the plant, what the other cannot absorb
        return min(m.left(chosen) for m in misfits)

    chosen: list[int] = []
    spent = 0.0
    while fits := [i for i, b in enumerate(blocks) if spent + b.expected_s <= budget_s]:
        reached = separation(chosen)
        best = max(fits, key=lambda i: (separation([*chosen, i]) - reached) / blocks[i].expected_s)
        chosen.append(best)
        spent += blocks[best].expected_s
    while True:  # the blocks' heat adds up: the plan must stay clear of the interlocks under either model
        steps = numbered([blocks[i] for i in chosen])
        hot = any(too_hot(predicted(r, steps, ambient_c, limits), limits) for r in (favoured, other))
        if len(chosen) == 1 or not hot:
            break
        chosen.pop()
    if hot:
        raise ValueError("every block heats the clutch beyond the over-temperature interlocks")
    diff = differences(favoured, other, steps, ambient_c, limits)
    rms = {c: float(np.sqrt(np.nanmean(d ** 2))) for c, d in diff.items() if c in noise}
    ratio = float(np.sqrt(np.mean([v ** 2 for v in favoured.rmse.values()])) / noise_floor(runs))
    return DiscriminationDesign(tuple(blocks[i] for i in chosen), steps, favoured.name, other.name, noise, rms,
                                noncentrality(diff, noise, rho), now,
                                forecast(favoured, other, steps, runs, ambient_c, limits), ratio)
