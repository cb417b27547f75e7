"""Parameter precision: the blocks that most shrink what the runs so far leave open.

Greedy D-optimal selection: starting from the information the runs already hold, add the candidate block
(`benchlab.design.blocks`) that raises log det of the information on the not-identified parameters most per
second of bench time (every other parameter a nuisance, `fisher.schur`), until no block fits the time budget. Each candidate's information is
predicted on its own from a bench at rest; the chosen plan is then predicted whole, and its expected standard
errors come from that.

The white-noise information understates a fit's standard errors (the input noise the thermal masses integrate,
coloured residuals: `benchlab.identify.uncertainty`); the expected errors are scaled by how much the parameter
file's own standard errors exceed the white-noise ones on the runs so far (the median ratio over the identified
parameters), which is printed.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from benchlab.design import fisher
from benchlab.design.blocks import Block, candidate_blocks, numbered, steady_schedule
from benchlab.identify.data import FitData
from benchlab.model.definition import ModelDefinition
from benchlab.network import ThermalNetwork
from benchlab.network.plant import NetworkPlant
from protocols.limits import BenchLimits
from protocols.schedule import Step, duration_s

if TYPE_CHECKING:
    from benchlab.design.points import RunsReading


@dataclass(frozen=True)
class PrecisionDesign:
    """The chosen blocks, their schedule, and the standard errors (share of the value) before and expected after."""

    blocks: tuple[Block, ...]
    steps: tuple[Step, ...]
    interest: tuple[str, ...]
    before: dict[str, float]
    expected: dict[str, float]
    calibration: float
    prior: np.ndarray  # the runs' information (ln θ of every free parameter), for what a sensor would add
    noise: dict[str, float]  # each measured channel's noise at the fitting step, K
    #: which identification the expected errors are of: "joint" (the designed run fitted together with the runs so
    #: far) or "cooldowns" (its cool-downs read one by one, eq. 11 fitted to their points: `design_cooldown_reading`)
    identification: str = "joint"
    #: the cool-down reading's points' disagreement with eq. (11) on the runs so far (`points.RunsReading`)
    disagreement: float = 1.0
    #: the cool-down reading's between-reading scatter each point is expected to carry, a share of R
    #: (`points.RunsReading`)
    scatter: float = 0.0

    def header(self) -> str:
        """What the expected errors are of, and their calibration."""
        if self.identification == "cooldowns":
            return (f"expected standard errors of eq. (11) fitted to the designed run's cool-downs, each read on its own "
                    f"(each point's error x {self.calibration:.2f}, the runs' misfit against the noise, and "
                    f"{100 * self.scatter:.1f} % of R beside it, the scatter of the runs' readings at one point; "
                    "now: the parameter file's):")
        return f"expected standard errors (white-noise information x {self.calibration:.2f}, the runs' own ratio):"

    def lines(self, params: Mapping[str, float]) -> list[str]:
        """The expected outcome, one line per parameter, for the terminal before the run."""
        out = [f"designed run: {len(self.blocks)} blocks, {sum(s.expected_s for s in self.steps) / 60:.1f} min",
               *(f"  block {i}: {b.name}" for i, b in enumerate(self.blocks)),
               self.header()]
        for name in self.interest:
            value = abs(params[name])
            now = f"{100 * self.before[name]:.0f} %" if np.isfinite(self.before[name]) else "not identified"
            out.append(f"  {name}: {now} of {params[name]:.4g} now -> "
                       f"{100 * self.expected[name]:.1f} % ({self.expected[name] * value:.3g}) after the run")
        return out


def calibration(info: np.ndarray, names: Sequence[str], params: Mapping[str, float],
                reported: Mapping[str, float], identified: Sequence[str]) -> float:
    """How much the parameter file's standard errors exceed the white-noise information's on the same runs: the
    median ratio over the identified parameters (1 where the file reports none)."""
    cov = np.linalg.inv(info + fisher.RIDGE * np.eye(len(names)))
    ratios = [reported[n] / abs(params[n]) / np.sqrt(cov[names.index(n), names.index(n)])
              for n in identified if n in reported and params[n] != 0 and cov[names.index(n), names.index(n)] > 0]
    ratios = [r for r in ratios if np.isfinite(r) and r > 0]
    return float(np.median(ratios)) if ratios else 1.0


def too_hot(data: FitData, limits: BenchLimits) -> bool:
    """Whether the predicted run comes within the interlocks' clear margin of an over-temperature limit."""
    peaks = {c: float(np.nanmax(v)) for c, v in data.targets.items()}
    return (peaks.get("T_flywheel", -np.inf) > limits.max_flywheel_c - limits.clear_margin_k
            or peaks.get("T_air", -np.inf) > limits.max_air_c - limits.clear_margin_k)


def greedy(gains: Sequence[np.ndarray], seconds: Sequence[float], start: np.ndarray, names: Sequence[str],
           interest: Sequence[str], budget_s: float, clear: Callable[[list[int]], bool] | None = None) -> list[int]:
    """Indices of the blocks (information `gains`, lengths `seconds`), the most log det on `interest` gained per
    second of bench time first, from the information `start`, until no block fits `budget_s`; with `clear`, only
    blocks after which the plan so far is still clear (of the interlocks, say)."""
    chosen: list[int] = []
    total, spent = start.copy(), 0.0
    while True:
        fits = [i for i, s in enumerate(seconds) if spent + s <= budget_s]
        now = fisher.log_det(total, names, interest)
        ranked = sorted(fits, key=lambda i: (fisher.log_det(total + gains[i], names, interest) - now) / seconds[i],
                        reverse=True)
        best = next((i for i in ranked if clear is None or clear([*chosen, i])), None)
        if best is None:
            return chosen
        chosen.append(best)
        total, spent = total + gains[best], spent + seconds[best]


def within_interlocks(blocks: Sequence[Block], chosen: list[int], params: Mapping[str, float],
                      network: ThermalNetwork, ambient_c: float, limits: BenchLimits,
                      ) -> tuple[list[int], tuple[Step, ...], FitData]:
    """The chosen blocks with blocks dropped from the end until the plan as predicted stays clear of the
    over-temperature interlocks (the blocks' heat adds up); its schedule and prediction. ValueError where even
    one block does not."""
    chosen = list(chosen)
    while True:
        steps = numbered([blocks[i] for i in chosen])
        predicted = fisher.predicted_data(steps, params, network, ambient_c, limits.drivetrain)
        if len(chosen) == 1 or not too_hot(predicted, limits):
            break
        chosen.pop()
    if too_hot(predicted, limits):
        raise ValueError("every block heats the clutch beyond the over-temperature interlocks")
    return chosen, steps, predicted


def design_precision(network: ThermalNetwork, params: Mapping[str, float], names: Sequence[str],
                     interest: Sequence[str], identified: Sequence[str], runs: Sequence[FitData],
                     reported: Mapping[str, float], limits: BenchLimits, ambient_c: float,
                     budget_s: float) -> PrecisionDesign:
    """Greedy D-optimal blocks within `budget_s` for `interest` (the most log det gained per second of bench time
    first), the runs' information the prior; the `identified` parameters calibrate the white-noise information
    against the parameter file's `reported` standard errors. ValueError when no block fits the budget."""
    blocks = [b for b in candidate_blocks(limits) if b.expected_s <= budget_s]
    if not blocks:
        raise ValueError("no block fits")
    noise = fisher.channel_noise(runs)
    prior = fisher.information(network, params, names, runs, noise)
    scale = calibration(prior, names, params, reported, identified)
    gains = [fisher.information(network, params, names,
                                [fisher.predicted_data(b.steps, params, network, ambient_c, limits.drivetrain)], noise)
             for b in blocks]
    chosen = greedy(gains, [b.expected_s for b in blocks], prior, names, interest, budget_s)
    chosen, steps, predicted = within_interlocks(blocks, chosen, params, network, ambient_c, limits)
    whole = fisher.information(network, params, names, [predicted], noise)
    before = {k: v * scale for k, v in fisher.relative_errors(prior, names, interest).items()}
    expected = {k: v * scale for k, v in fisher.relative_errors(prior + whole, names, interest).items()}
    return PrecisionDesign(tuple(blocks[i] for i in chosen), steps, tuple(interest), dict(before), expected, scale,
                           prior, noise, "joint")


def repeats_apart(chosen: Sequence[int], point: Callable[[int], object]) -> list[int]:
    """The blocks in `chosen` order, but an operating point chosen more than once (the first such) read first and
    last: the repeat then spans the run's history, which moves a reading (docs/design.md), so eq. (11)'s fit sees
    the scatter instead of two readings taken a cycle apart that agree (seeds 103 and 104: 500 rpm read in
    consecutive cycles agreed, the scatter read 0 and the errors 2-6 times below the run-to-run spread)."""
    counts = Counter(point(i) for i in chosen)
    repeated = next((p for p in (point(i) for i in chosen) if counts[p] > 1), None)
    if repeated is None:
        return list(chosen)
    own = [i for i in chosen if point(i) == repeated]
    return [own[0], *(i for i in chosen if point(i) != repeated), *own[1:]]


def design_cooldown_reading(network: ThermalNetwork, params: Mapping[str, float], names: Sequence[str],
                            interest: Sequence[str], runs: Sequence[FitData], before: Mapping[str, float],
                            fitting: Mapping[str, object], reading: RunsReading, limits: BenchLimits,
                            ambient_c: float, budget_s: float, blocks: Sequence[Block], plant: NetworkPlant,
                            model: ModelDefinition | None = None) -> PrecisionDesign:
    """Greedy D-optimal steady `blocks` (`blocks.steady_blocks`) within `budget_s` for `interest` (parameters of
    eq. 11) as the designed run's cool-downs read one by one (with `model`'s structure where given, as the reading
    does) give them (`benchlab.design.points`): each point's expected error is its reading's, scaled by the misfit
    the runs so far show (`points.misfit_factor`, printed as the calibration), and beside it the between-reading
    scatter of the runs so far read alike (`reading.scatter`: a reading depends on the run's history, which no
    segment's residuals show); eq. (11)'s expected errors are those of the points' information. `before` is the
    parameter file's own share of each value. A block is taken only where the plan with it, timed in sequence on
    `plant` (the model at the parameter file's values, which predict the runs' temperatures: `params` hold eq. 11's
    design values) by `blocks.steady_schedule`, fits the budget and stays clear of the interlocks there; ranked by
    its information per second of bench time where it follows another block. ValueError when no block fits."""
    from benchlab.design import points

    blocks = [b for b in blocks if b.expected_s <= budget_s]
    if not blocks:
        raise ValueError("no block fits")
    noise = fisher.channel_noise(runs)
    scale = points.misfit_factor(fitting, noise)
    gains = [points.point_information(b, params, float(np.hypot(
        scale * points.point_error(b, params, network, ambient_c, limits, noise, model), reading.scatter)))
        for b in blocks]
    following = [duration_s(steady_schedule([b, b], limits, plant)) - b.expected_s for b in blocks]
    start = np.zeros((len(points.EQ11), len(points.EQ11)))

    def fits(chosen: list[int]) -> bool:  # the plan timed in sequence: within the budget, clear of the interlocks
        steps = steady_schedule([blocks[i] for i in chosen], limits, plant)
        return duration_s(steps) <= budget_s and not too_hot(
            fisher.predicted_data(steps, plant.params, network, ambient_c, limits.drivetrain), limits)

    chosen = greedy(gains, following, start, points.EQ11, interest, math.inf, fits)
    if not chosen:
        raise ValueError("no block fits")
    apart = repeats_apart(chosen, lambda i: tuple(sorted(points.operating_point(blocks[i]).items())))
    chosen = apart if fits(apart) else chosen
    steps = steady_schedule([blocks[i] for i in chosen], limits, plant)
    total = sum((gains[i] for i in chosen), start)
    expected = fisher.relative_errors(total, points.EQ11, interest)
    prior = fisher.information(network, params, names, runs, noise)  # for what a sensor would add
    return PrecisionDesign(tuple(blocks[i] for i in chosen), steps, tuple(interest), dict(before), expected, scale,
                           prior, noise, "cooldowns", reading.disagreement, reading.scatter)
