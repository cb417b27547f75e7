"""Discrimination: the blocks that most separate two competing models (diagnose's tied alternatives, or a cause
against the model without it), each refitted to the runs so far.

T-optimal: the criterion is the expected sum of squared differences of the measured channels between the two
models' predictions of the designed run, each channel weighted by its noise (the non-centrality of the test
between them under white noise). Greedy like the precision design (`benchlab.design.precision`): the block that
adds most of it per second of bench time first, each block predicted from a bench at rest; then the chosen plan
predicted whole for the expected outcome.

The noise a difference is weighed against is each channel's misfit of the better model on the runs so far (its
in-sample residual RMS), not the sensors' white noise: what the models cannot explain of the runs they were fitted
to counts as noise for telling them apart. That misfit is far from white at diagnose's 1 s step, so the statistic
counts effective samples, n (1 − ρ) / (1 + ρ) with ρ the residuals' lag-1 autocorrelation (as diagnose's BIC does).
Everything is at diagnose's step (`engine.STEP_S`), so the statistic of the designed run and of the runs so far
are on one scale.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from benchlab.design import fisher
from benchlab.design.blocks import Block, candidate_blocks, numbered
from benchlab.design.precision import too_hot
from benchlab.diagnose.engine import ALPHA  # the level the loser must be beaten at: diagnose's
from benchlab.diagnose.engine import BLOCK_S, STEP_S
from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import simulate_outputs
from benchlab.network import ThermalNetwork
from protocols.limits import BenchLimits
from protocols.schedule import Step


@dataclass(frozen=True)
class Rival:
    """One competing model: its name (diagnose's candidate key, or the model's), network and refitted values."""

    name: str
    network: ThermalNetwork
    params: Mapping[str, float]
    rmse: Mapping[str, float]  # each measured channel's in-sample residual RMS on the runs so far, K
    rho: float  # lag-1 autocorrelation of those residuals, pooled over channels and runs (0 to 0.99)


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


def block_log_ratios(favoured: Mapping[str, np.ndarray], other: Mapping[str, np.ndarray]) -> np.ndarray:
    """Diagnose's unit of the contest (`engine.block_test`): per BLOCK_S block of a run at its step STEP_S, the log
    of the other model's mean squared error over the favoured's, the channels' squared errors pooled."""
    block_len = max(1, int(BLOCK_S / STEP_S))
    n = max((len(v) for v in favoured.values()), default=0)
    ratios = []
    for start in range(0, n, block_len):
        pair = [(favoured[c][start:start + block_len], other[c][start:start + block_len]) for c in favoured if c in other]
        f = np.concatenate([a[np.isfinite(a) & np.isfinite(b)] for a, b in pair])
        o = np.concatenate([b[np.isfinite(a) & np.isfinite(b)] for a, b in pair])
        if f.size and f.mean() > 0:
            ratios.append(float(np.log(o.mean() / f.mean())))
    return np.array(ratios)


def expected_block_test(diff: Mapping[str, np.ndarray], noise: Mapping[str, float],
                        spread: float) -> tuple[float, float, int]:
    """The block test diagnose will run on the designed run, expected: per block the favoured at its misfit and the
    other at the misfit plus the predicted difference (`block_log_ratios`), against the blocks' own spread and
    `spread`, the spread of that log ratio from block to block on the runs so far (what the prediction cannot
    see). The t statistic, its one-sided p-value and the number of blocks (p = 1 below 3 blocks, as the test)."""
    squared_fav = {c: np.where(np.isfinite(d), noise[c] ** 2, np.nan) for c, d in diff.items() if c in noise}
    squared_other = {c: noise[c] ** 2 + diff[c] ** 2 for c in squared_fav}
    ratios = block_log_ratios(squared_fav, squared_other)
    if len(ratios) < 3:
        return 0.0, 1.0, len(ratios)
    sd = float(np.sqrt(np.var(ratios, ddof=1) + spread ** 2))
    t = float(np.mean(ratios) / (sd / np.sqrt(len(ratios)))) if sd > 0 else np.inf
    return t, float(stats.t.sf(t, len(ratios) - 1)), len(ratios)


def runs_spread(favoured: "Rival", other: "Rival", runs: Sequence[FitData]) -> float:
    """The standard deviation of `block_log_ratios` of the two rivals' squared residuals on the runs so far, over
    their blocks: how much the contest's unit varies where neither prediction sees why."""
    ratios = []
    for data in runs:
        sims = [simulate_outputs(r.network, r.params, data) for r in (favoured, other)]
        squared = [{c: (data.targets[c] - sim[c]) ** 2 for c in sim if c in data.targets} for sim in sims]
        ratios.append(block_log_ratios(*squared))
    pooled = np.concatenate(ratios) if ratios else np.array([])
    return float(np.std(pooled, ddof=1)) if pooled.size > 1 else 0.0


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
    #: diagnose's block test on the run, expected (`expected_block_test`): t, p and the blocks it counts
    block_t: float = 0.0
    block_p: float = 1.0
    block_count: int = 0

    @property
    def expected_rmse_gap(self) -> float:
        """How much the loser's RMSE should exceed the survivor's on the run (K, over the channels): the survivor at
        the noise, the loser at the noise and the difference added in quadrature."""
        gaps = [np.sqrt(self.noise[c] ** 2 + d ** 2) - self.noise[c] for c, d in self.rms_difference.items()]
        return float(np.mean(gaps)) if gaps else 0.0

    @property
    def p_value(self) -> float:
        """The test between the two at the expected statistic (chi-square, one degree of freedom)."""
        return float(stats.chi2.sf(self.statistic, 1))

    def lines(self) -> list[str]:
        """The expected outcome, for the terminal before the run."""
        verdict = "should be beaten" if self.block_p < ALPHA else "may not be beaten"
        return [f"designed run: {len(self.blocks)} blocks, {sum(s.expected_s for s in self.steps) / 60:.1f} min",
                *(f"  block {i}: {b.name}" for i, b in enumerate(self.blocks)),
                f"to tell apart {self.favoured} (taken as right) and {self.other}:",
                *(f"  {c}: the two differ by {d:.3f} K RMS on the run against a misfit of {self.noise[c]:.3f} K"
                  for c, d in self.rms_difference.items()),
                f"expected: {self.other} {verdict} at alpha {ALPHA:g} by diagnose's block test ({self.block_count} "
                f"blocks of {BLOCK_S:g} s: t = {self.block_t:.2f}, p = {self.block_p:.2g}), its RMSE "
                f"{self.expected_rmse_gap:.3f} K above {self.favoured}'s; sample statistic {self.statistic:.1f} (runs "
                f"so far {self.statistic_now:.1f})"]


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
    gains = [noncentrality(differences(favoured, other, b.steps, ambient_c, limits), noise, rho) for b in blocks]
    chosen: list[int] = []
    spent = 0.0
    while fits := [i for i, b in enumerate(blocks) if spent + b.expected_s <= budget_s]:
        best = max(fits, key=lambda i: gains[i] / blocks[i].expected_s)
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
    t, p, count = expected_block_test(diff, noise, runs_spread(favoured, other, runs))
    return DiscriminationDesign(tuple(blocks[i] for i in chosen), steps, favoured.name, other.name, noise, rms,
                                noncentrality(diff, noise, rho), now, t, p, count)
