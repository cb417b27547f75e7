"""Diagnose accuracy: how large must a hidden effect be to be named, and how often is a correct model accused?

    .venv/bin/python benchmarks/accuracy_diagnose.py [--quick] [--seeds N]

1. Detection versus magnitude. For each effect of the simulated bench, a geometric ladder of magnitudes
   from clearly below to clearly above what the 0.01 K sensor-noise floor lets one see; per magnitude,
   N seeds (default 3) of a 1 h Table 1 run on the paper's nonlinear clutch plus that one effect,
   diagnosed with the nonlinear baseline. Per cell: the share of runs whose first finding names the
   effect (signal and mechanism as the effect declares them), whose first finding names something
   else, and with no finding; the mean |gain - truth's gain| in points over the correctly named runs;
   and the baseline's held-out RMSE over the floor (the effect's size as the baseline sees it). The
   floor is the RMSE of the true sensor temperatures against the fitting targets, what a perfect model
   scores; the truth's gain is 1 - floor / baseline RMSE. These few lines are the ones of
   tests/test_diagnose.py, written again here (a benchmark does not import from the tests).
   The detection limit of an effect is its weakest magnitude named first in all seeds; stronger
   magnitudes that were not are listed beside it.
2. False findings. 20 seeds of the correct model (nonlinear truth, nonlinear baseline) and 6 of a
   linear truth with the linear baseline: runs with any finding, with a 95 % Clopper-Pearson interval.

Cases run one after another (diagnose itself uses every core). --quick: every other magnitude from the
strongest down, one seed, 4 + 2 false-finding seeds (~3 min). Full run 11-13 min on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from benchlab.diagnose import diagnose
from benchlab.diagnose.engine import STEP_S
from benchlab.identify.data import prepare
from benchlab.params import paper_params
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

HOUR_S = 3600.0
LADDER_SEED = 1001  # seeds 1001, 1002, ... for every cell: not used by any test
CORRECT_SEED = 1101  # 20 nonlinear runs from here
LINEAR_SEED = 1201  # 6 linear runs from here
CORRECT_RUNS, LINEAR_RUNS = 20, 6
CONFIDENCE = 0.95


def _torque_heat(watts: float) -> P.Effect:
    """Heat into the chamber air saturating with clutch torque: a shape no physical candidate has."""
    return P.custom_source("torque_heat", "A", "clutch_torque", "other",
                           lambda ch: watts * np.tanh(np.abs(ch["clutch_torque"]) / 40.0))


@dataclass(frozen=True)
class Ladder:
    """An effect's magnitudes, weakest first, and how to build the effect at one of them."""

    name: str
    unit: str
    magnitudes: tuple[float, ...]
    build: Callable[[float], P.Effect]


LADDERS = (  # steps of about 3x (2x where the error grows faster), set from a one-seed probe of each effect
    Ladder("slip_convection", "g per 1000 rpm", (0.006, 0.02, 0.06, 0.2), P.slip_convection),
    Ladder("heat_split", "plate share", (0.504, 0.512, 0.535, 0.6, 0.7), P.heat_split),
    Ladder("gearbox_churning", "W at 2000 rpm", (1.5, 4.5, 13.0, 40.0), P.gearbox_churning),
    Ladder("engine_heat", "W at 2000 rpm", (0.1, 0.3, 1.0, 3.0), P.engine_heat),
    Ladder("plate_conduction", "R_PF K/W", (50.0, 15.0, 5.0, 1.5), P.plate_conduction),
    Ladder("sensor_lag", "tau_F s", (0.06, 0.2, 0.6, 2.0), P.sensor_lag),
    Ladder("extra_mass", "C_H J/K, R 0.2 K/W", (25.0, 50.0, 100.0, 200.0, 400.0), lambda c: P.extra_mass(c, 0.2)),
    Ladder("radiation", "eps*A m2", (0.005, 0.015, 0.045, 0.15), P.radiation),
    Ladder("torque_heat (custom)", "W into air", (1.0, 3.0, 9.0, 27.0), _torque_heat),
)


@dataclass(frozen=True)
class Case:
    """One diagnosed run: what was named (signal, mechanism, gain), the floor and the baseline's error."""

    named: tuple[tuple[str | None, str, float], ...]
    floor_k: float
    baseline_k: float
    seconds: float

    @property
    def ratio(self) -> float:
        """Baseline held-out RMSE over the floor."""
        return self.baseline_k / self.floor_k

    @property
    def true_gain_pct(self) -> float:
        """The gain a perfect model would show: 1 - floor / baseline RMSE, in %."""
        return 100.0 * (1.0 - self.floor_k / self.baseline_k)


def floor_k(plant: P.ThermalPlant, run) -> float:
    """RMSE of the true sensor temperatures against the fitting targets: what a perfect model scores."""
    data = prepare(run, STEP_S)
    truth = plant.sensor_temperatures(run.attrs["true_states"])
    squared = [(truth[c][:: data.block][: len(t)][np.isfinite(t)] - t[np.isfinite(t)]) ** 2
               for c, t in data.targets.items()]
    return float(np.sqrt(np.mean(np.concatenate(squared))))


def run_case(effects: list[P.Effect], seed: int, truth: str) -> Case:
    """Simulate a 1 h Table 1 run of `truth` plus `effects` and diagnose it with `truth` as the baseline."""
    plant = P.ThermalPlant(paper_params(truth), effects)
    run = run_schedule(table1_schedule(seed, duration_s=HOUR_S), plant, seed=seed)
    start = time.perf_counter()
    result = diagnose([run], baseline=truth)
    seconds = time.perf_counter() - start
    named = tuple((f["signal"], f["mechanism"], f["gain_pct"]) for f in result["findings"])
    return Case(named, floor_k(plant, run), result["baseline"]["rmse_K"], seconds)


def describe(case: Case) -> str:
    """The case's findings as 'signal/mechanism gain%', or 'nothing'."""
    return ", ".join(f"{s}/{m} {g:.1f}%" for s, m, g in case.named) or "nothing"


@dataclass(frozen=True)
class Cell:
    """All seeds of one effect at one magnitude."""

    ladder: Ladder
    magnitude: float
    expected: tuple[str | None, str]
    cases: tuple[Case, ...]

    def first(self, case: Case) -> tuple[str | None, str] | None:
        """(signal, mechanism) of the case's first finding, None if it has none."""
        return case.named[0][:2] if case.named else None

    @property
    def right(self) -> list[Case]:
        """Cases whose first finding names the effect."""
        return [c for c in self.cases if self.first(c) == self.expected]

    @property
    def wrong(self) -> list[Case]:
        """Cases whose first finding names something else."""
        return [c for c in self.cases if self.first(c) not in (None, self.expected)]

    @property
    def empty(self) -> list[Case]:
        """Cases with no finding."""
        return [c for c in self.cases if not c.named]

    @property
    def all_named(self) -> bool:
        """Every seed named the effect first."""
        return len(self.right) == len(self.cases)

    def row(self) -> str:
        """A markdown table row."""
        n = len(self.cases)
        gain = (f"{np.mean([abs(c.named[0][2] - c.true_gain_pct) for c in self.right]):.1f}"
                if self.right else "-")
        instead = "; ".join(sorted({"/".join(map(str, self.first(c))) for c in self.wrong})) or ""
        ratio = np.mean([c.ratio for c in self.cases])
        return (f"| {self.ladder.name} | {self.magnitude:g} | {ratio:.2f} | {len(self.right)}/{n} | "
                f"{len(self.wrong)}/{n} | {len(self.empty)}/{n} | {gain} | {instead} |")


def detection_limit(cells: list[Cell]) -> tuple[Cell | None, list[Cell]]:
    """The weakest cell of a ladder named first in all seeds, and the stronger cells that were not."""
    limit = next((cell for cell in cells if cell.all_named), None)
    stronger = cells[cells.index(limit) + 1:] if limit else []
    return limit, [cell for cell in stronger if not cell.all_named]


def clopper_pearson(k: int, n: int) -> tuple[float, float]:
    """Two-sided CONFIDENCE Clopper-Pearson interval of a binomial rate k / n."""
    alpha = 1.0 - CONFIDENCE
    low = float(stats.beta.ppf(alpha / 2, k, n - k + 1)) if k > 0 else 0.0
    high = float(stats.beta.ppf(1 - alpha / 2, k + 1, n - k)) if k < n else 1.0
    return low, high


def ladder_study(ladders: tuple[Ladder, ...], seeds: int, quick: bool) -> list[list[Cell]]:
    """Every ladder's cells, weakest magnitude first; one line a case as it finishes."""
    study = []
    for ladder in ladders:
        magnitudes = ladder.magnitudes[::-2][::-1] if quick else ladder.magnitudes
        cells = []
        for magnitude in magnitudes:
            effect = ladder.build(magnitude)
            cases = []
            for seed in range(LADDER_SEED, LADDER_SEED + seeds):
                case = run_case([effect], seed, "nonlinear")
                cases.append(case)
                print(f"  {ladder.name} {magnitude:g} seed {seed}: baseline/floor {case.ratio:.2f}, truth's gain "
                      f"{case.true_gain_pct:.1f}%, found {describe(case)} ({case.seconds:.1f} s)", flush=True)
            cells.append(Cell(ladder, magnitude, (effect.signal, effect.mechanism), tuple(cases)))
        study.append(cells)
    return study


def false_study(correct_runs: int, linear_runs: int) -> list[Case]:
    """Diagnoses of runs whose baseline is the truth: nonlinear/nonlinear, then linear/linear."""
    cases = []
    for truth, first, count in (("nonlinear", CORRECT_SEED, correct_runs), ("linear", LINEAR_SEED, linear_runs)):
        for seed in range(first, first + count):
            case = run_case([], seed, truth)
            cases.append(case)
            print(f"  correct {truth} seed {seed}: baseline/floor {case.ratio:.3f}, found {describe(case)} "
                  f"({case.seconds:.1f} s)", flush=True)
    return cases


def main() -> None:
    """Run both studies and print the detection table, the limits and the false-finding rate."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="half the magnitudes, one seed, 4 + 2 correct runs")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per magnitude (default 3; --quick: 1)")
    args = parser.parse_args()
    seeds = args.seeds or (1 if args.quick else 3)
    start, load_start = time.perf_counter(), os.getloadavg()[0]
    print(f"detection vs magnitude: {seeds} seed(s) per cell from {LADDER_SEED}, 1 h Table 1 runs", flush=True)
    study = ladder_study(LADDERS, seeds, args.quick)
    print("false findings", flush=True)
    false = false_study(*((4, 2) if args.quick else (CORRECT_RUNS, LINEAR_RUNS)))

    print("\n| effect | magnitude | baseline/floor | named first | wrong first | nothing | mean abs(gain - truth) pts "
          "| named instead |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for cells in study:
        for cell in cells:
            print(cell.row())
    print("\n| effect | unit | detection limit | baseline/floor there | stronger, not named in all seeds |")
    print("| --- | --- | --- | --- | --- |")
    for cells in study:
        limit, missed = detection_limit(cells)
        where = (f"{limit.magnitude:g} | {np.mean([c.ratio for c in limit.cases]):.2f}" if limit
                 else "not reached on the ladder | -")
        holes = ", ".join(f"{c.magnitude:g} ({len(c.right)}/{len(c.cases)})" for c in missed)
        print(f"| {cells[0].ladder.name} | {cells[0].ladder.unit} | {where} | {holes} |")

    accused = sum(1 for c in false if c.named)
    low, high = clopper_pearson(accused, len(false))
    findings = sum(len(c.named) for c in false)
    print(f"\nfalse findings: {accused}/{len(false)} correct-model runs with a finding ({findings} findings in all), "
          f"rate {accused / len(false):.3f}, {CONFIDENCE:.0%} Clopper-Pearson [{low:.3f}, {high:.3f}]")
    total = time.perf_counter() - start
    diagnosing = sum(c.seconds for cells in study for cell in cells for c in cell.cases) + sum(c.seconds for c in false)
    print(f"wall time {total:.0f} s ({total / 60:.1f} min), diagnose alone {diagnosing:.0f} s; "
          f"load average {load_start:.2f} at the start, {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
