"""Diagnose accuracy: how large must a hidden effect be to be named, and how often is a correct model accused?

    .venv/bin/python benchmarks/accuracy_diagnose.py [--quick] [--seeds N] [--only NAME ...]

1. Detection versus magnitude. For each effect of the simulated bench, a geometric ladder of magnitudes
   from clearly below to clearly above what the 0.01 K sensor-noise floor lets one see; per magnitude,
   N seeds (default 3) of a 1 h Table 1 run on the paper's nonlinear clutch plus that one effect,
   diagnosed with the nonlinear baseline. The effects of `sim_bench.plant` were written beside diagnose's
   library; those of `sim_bench.unseen` (marked "unseen") were not: laws no candidate has, in places the
   library never looked (issue 18). Per cell: the share of runs whose first finding names the
   effect (a mechanism and signal `Hidden.named` accepts; the two-effect ladder: both effects named and
   nothing else), whose first finding names something else, and with no finding; the mean |gain - truth's gain| in points over the correctly named runs;
   and the baseline's held-out RMSE over the floor (the effect's size as the baseline sees it). The
   floor is the RMSE of the true sensor temperatures against the fitting targets, what a perfect model
   scores; the truth's gain is 1 - floor / baseline RMSE. These few lines are the ones of
   tests/test_diagnose.py, written again here (a benchmark does not import from the tests).
   The detection limit of an effect is its weakest magnitude named first in all seeds; stronger
   magnitudes that were not are listed beside it.
2. False findings. 28 seeds of the correct model (nonlinear truth, nonlinear baseline) and 8 of a
   linear truth with the linear baseline, simulated in whole arrays (`sim_bench.virtual_run`), plus 2 + 2
   1 h Table 1 runs through the runner, the drivers and the emulated devices (`benchlab.runner.session`,
   as `benchlab run` and `benchlab pipeline` make them): runs with any finding, with a 95 %
   Clopper-Pearson interval.

Cases run one after another (diagnose itself uses every core). --quick: every other magnitude from the
strongest down, one seed, 4 + 2 batch and 1 + 1 driver false-finding runs. --only NAME ...: only these
ladders (their names as printed; `unseen` for all of sim_bench.unseen's) and, with `false_findings`, the
false-finding study. Full run about an hour on 2 cores (unseen ladders 33 min, false findings 18 min for 40 runs, the ladders
of sim_bench.plant 11 min).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from benchlab.diagnose import diagnose
from benchlab.diagnose.engine import STEP_S
from benchlab.identify.data import prepare
from benchlab.model.params import paper_params
from benchlab.runfile import load_run, load_truth
from benchlab.runner.session import RunRequest, execute
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.bench import SimulatedBench
from sim_bench import unseen as U
from sim_bench.virtual_run import run_schedule

HOUR_S = 3600.0
LADDER_SEED = 1001  # seeds 1001, 1002, ... for every cell: not used by any test
CORRECT_SEED = 1101  # 20 nonlinear runs from here
LINEAR_SEED = 1201  # 8 linear runs from here
DRIVER_SEED = 1301  # runs through the drivers: nonlinear from here, linear after them
CORRECT_RUNS, LINEAR_RUNS, DRIVER_RUNS = 28, 8, 2  # DRIVER_RUNS of each truth: 40 correct-model runs in all (issue 31)
QUICK_RUNS = (4, 2, 1)
FALSE_FINDINGS = "false_findings"
CONFIDENCE = 0.95


Named = tuple[tuple[str | None, str, float], ...]  # a diagnosis' findings: (signal, mechanism, gain %) each


def _torque_heat(watts: float) -> P.Effect:
    """Heat into the chamber air saturating with clutch torque: a shape no physical candidate has."""
    return P.custom_source("torque_heat", "A", "clutch_torque", "other",
                           lambda ch: watts * np.tanh(np.abs(ch["clutch_torque"]) / 40.0))


def _declared(build: Callable[..., P.Effect]) -> Callable[..., U.Hidden]:
    """A sim_bench.plant effect builder as one of hidden effects named right by what they declare."""
    return lambda *args: U.Hidden.declared(build(*args))


def _cover(size: float) -> U.Hidden:
    """The plate cover scaled as a whole: 2500·size J/K behind 0.1/size K/W on either side (size 1: the test's)."""
    return U.plate_cover(2500.0 * size, 0.1 / size, 0.1 / size)


PAPER_CONVECTION = ("engine_speed", "convection")  # what the linear baseline lacks on the nonlinear clutch


@dataclass(frozen=True)
class Ladder:
    """An effect's magnitudes, weakest first, how to build it at one of them, the baseline it is diagnosed
    from and the findings expected besides it (effects of the truth the baseline lacks)."""

    name: str
    unit: str
    magnitudes: tuple[float, ...]
    build: Callable[[float], U.Hidden]
    baseline: str = "nonlinear"
    also: tuple[tuple[str | None, str], ...] = ()

    def right(self, hidden: U.Hidden, named: Named) -> bool:
        """Whether the findings name the effect: first; or, with `also`, it and them, nothing else."""
        pairs = [n[:2] for n in named]
        if not self.also:
            return bool(pairs) and hidden.named(*pairs[0])
        return (len(pairs) == len(self.also) + 1 and sum(hidden.named(*p) for p in pairs) == 1
                and all(a in pairs for a in self.also))


LADDERS = (  # steps of about 3x (2x where the error grows faster), set from a one-seed probe of each effect
    Ladder("slip_convection", "g per 1000 rpm", (0.006, 0.02, 0.06, 0.2), _declared(P.slip_convection)),
    Ladder("heat_split", "plate share", (0.504, 0.512, 0.535, 0.6, 0.7), _declared(P.heat_split)),
    Ladder("gearbox_churning", "W at 2000 rpm", (1.5, 4.5, 13.0, 40.0), _declared(P.gearbox_churning)),
    Ladder("engine_heat", "W at 2000 rpm", (0.1, 0.3, 1.0, 3.0), _declared(P.engine_heat)),
    Ladder("plate_conduction", "R_PF K/W", (50.0, 15.0, 5.0, 1.5), _declared(P.plate_conduction)),
    Ladder("contact_torque", "R_PF K/W at 100 N*m", (5.0, 1.5, 0.5, 0.15),
           _declared(lambda r: P.contact_conduction(r, "clutch_torque", 100.0))),
    Ladder("sensor_lag", "tau_F s", (0.06, 0.2, 0.6, 2.0), _declared(P.sensor_lag)),
    Ladder("extra_mass", "C_H J/K, R 0.2 K/W", (25.0, 50.0, 100.0, 200.0, 400.0),
           _declared(lambda c: P.extra_mass(c, 0.2))),
    Ladder("radiation", "eps*A m2", (0.005, 0.015, 0.045, 0.15), _declared(P.radiation)),
    Ladder("torque_heat (custom)", "W into air", (1.0, 3.0, 9.0, 27.0), _declared(_torque_heat)),
    # sim_bench.unseen: ladders from a one-seed probe of the baseline's in-sample RMSE over the floor (seed 2001)
    Ladder("plate_cover (unseen)", "size: 2500 J/K, 0.1 K/W at 1", (0.03, 0.1, 0.3, 1.0), _cover),
    Ladder("release_bearing_heat (unseen)", "W while open", (1.0, 3.0, 10.0, 30.0), U.release_bearing_heat),
    Ladder("release_path_conduction (unseen)", "R_PT K/W", (10.0, 3.0, 1.0, 0.3, 0.1), U.release_path_conduction),
    Ladder("air_sensor_lag (unseen)", "tau_A s", (0.5, 1.5, 5.0, 15.0), U.air_sensor_lag),
    Ladder("gear_mesh_loss (unseen)", "W at 300 N*m, 2000 rpm", (1.5, 5.0, 15.0, 45.0), U.gear_mesh_loss),
    Ladder("convection+gear_mesh_loss (unseen, linear baseline)", "W at 300 N*m, 2000 rpm",
           (5.0, 15.0, 45.0), U.gear_mesh_loss, baseline="linear", also=(PAPER_CONVECTION,)),
)


@dataclass(frozen=True)
class Case:
    """One diagnosed run: what was named (signal, mechanism, gain), the floor and the baseline's error."""

    named: Named
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


def floor_k(run: pd.DataFrame, at_sensors: Mapping[str, np.ndarray]) -> float:
    """RMSE of the true sensor temperatures (measured channel -> values on the run's grid) against the fitting
    targets: what a perfect model scores."""
    data = prepare(run, STEP_S)
    squared = [(np.asarray(at_sensors[c])[:: data.block][: len(t)][np.isfinite(t)] - t[np.isfinite(t)]) ** 2
               for c, t in data.targets.items()]
    return float(np.sqrt(np.mean(np.concatenate(squared))))


def batch_floor_k(plant: P.ThermalPlant, run: pd.DataFrame) -> float:
    """The floor of a run of `sim_bench.virtual_run`, whose true states it carries."""
    return floor_k(run, plant.sensor_temperatures(run.attrs["true_states"]))


def diagnosed(run: pd.DataFrame, baseline: str, floor: float) -> Case:
    """Diagnose one run from `baseline`; what it named, timed."""
    start = time.perf_counter()
    result = diagnose([run], baseline=baseline)
    seconds = time.perf_counter() - start
    named = tuple((f["signal"], f["mechanism"], f["gain_pct"]) for f in result["findings"])
    return Case(named, floor, result["baseline"]["rmse_K"], seconds)


def run_case(effects: list[P.Effect], seed: int, truth: str, baseline: str | None = None) -> Case:
    """Simulate a 1 h Table 1 run of `truth` plus `effects` and diagnose it from `baseline` (default: the truth)."""
    plant = P.ThermalPlant(paper_params(truth), effects)
    run = run_schedule(table1_schedule(seed, duration_s=HOUR_S), plant, seed=seed)
    return diagnosed(run, baseline or truth, batch_floor_k(plant, run))


def driver_case(seed: int, truth: str) -> Case:
    """A 1 h Table 1 run of `truth` through the runner, the drivers and the emulated bench, diagnosed from the
    truth; the floor from the run file's /truth."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "table1.h5"
        code, summary = execute(RunRequest(protocol="table1", out=path, seed=seed, duration_s=HOUR_S,
                                           bench=SimulatedBench(P.ThermalPlant(paper_params(truth))),
                                           install_signals=False))
        if code != 0:
            raise RuntimeError(f"driver run seed {seed} ended {summary.status if summary else '?'} (exit {code})")
        run, truth_frame = load_run(path), load_truth(path)
    return diagnosed(run, truth, floor_k(run, {c: truth_frame[c].to_numpy() for c in truth_frame.columns}))


def describe(case: Case) -> str:
    """The case's findings as 'signal/mechanism gain%', or 'nothing'."""
    return ", ".join(f"{s}/{m} {g:.1f}%" for s, m, g in case.named) or "nothing"


@dataclass(frozen=True)
class Cell:
    """All seeds of one effect at one magnitude."""

    ladder: Ladder
    magnitude: float
    hidden: U.Hidden
    cases: tuple[Case, ...]

    @property
    def right(self) -> list[Case]:
        """Cases whose findings name the effect (the ladder's `right`)."""
        return [c for c in self.cases if self.ladder.right(self.hidden, c.named)]

    @property
    def wrong(self) -> list[Case]:
        """Cases with findings that do not name the effect."""
        return [c for c in self.cases if c.named and not self.ladder.right(self.hidden, c.named)]

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
        shown = (lambda c: c.named) if self.ladder.also else (lambda c: c.named[:1])
        instead = "; ".join(sorted({" + ".join(f"{s}/{m}" for s, m, _ in shown(c)) for c in self.wrong}))
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
            hidden = ladder.build(magnitude)
            cases = []
            for seed in range(LADDER_SEED, LADDER_SEED + seeds):
                case = run_case([hidden.effect], seed, "nonlinear", ladder.baseline)
                cases.append(case)
                print(f"  {ladder.name} {magnitude:g} seed {seed}: baseline/floor {case.ratio:.2f}, truth's gain "
                      f"{case.true_gain_pct:.1f}%, found {describe(case)} ({case.seconds:.1f} s)", flush=True)
            cells.append(Cell(ladder, magnitude, hidden, tuple(cases)))
        study.append(cells)
    return study


def false_study(correct_runs: int, linear_runs: int, driver_runs: int) -> list[tuple[str, Case]]:
    """Diagnoses of runs whose baseline is the truth, each with its group: nonlinear/nonlinear and linear/linear
    batch-simulated, then `driver_runs` of each truth through the drivers."""
    plan = [(truth, seed, False) for truth, first, count in
            (("nonlinear", CORRECT_SEED, correct_runs), ("linear", LINEAR_SEED, linear_runs))
            for seed in range(first, first + count)]
    plan += [(truth, DRIVER_SEED + offset + i, True)
             for offset, truth in ((0, "nonlinear"), (DRIVER_RUNS, "linear")) for i in range(driver_runs)]
    cases = []
    for truth, seed, through_drivers in plan:
        group = f"{truth}, {'drivers' if through_drivers else 'batch'}"
        case = driver_case(seed, truth) if through_drivers else run_case([], seed, truth)
        cases.append((group, case))
        print(f"  correct {group} seed {seed}: baseline/floor {case.ratio:.3f}, found {describe(case)} "
              f"({case.seconds:.1f} s)", flush=True)
    return cases


def false_rate(label: str, cases: list[Case]) -> str:
    """Runs with a finding among `cases`, the rate and its Clopper-Pearson interval, as one line."""
    accused = sum(1 for c in cases if c.named)
    low, high = clopper_pearson(accused, len(cases))
    return (f"{label}: {accused}/{len(cases)} correct-model runs with a finding "
            f"({sum(len(c.named) for c in cases)} findings in all), rate {accused / len(cases):.3f}, "
            f"{CONFIDENCE:.0%} Clopper-Pearson [{low:.3f}, {high:.3f}]")


def selected(only: list[str] | None) -> tuple[tuple[Ladder, ...], bool]:
    """The ladders `--only` names (a ladder's name, its first word, or `unseen`) and whether the false-finding
    study runs; everything without `--only`."""
    if not only:
        return LADDERS, True
    known = {FALSE_FINDINGS, "unseen"} | {l.name for l in LADDERS} | {l.name.split()[0] for l in LADDERS}
    unknown = [name for name in only if name not in known]
    if unknown:
        raise SystemExit(f"--only: unknown {unknown}; known: {sorted(known)}")
    ladders = tuple(l for l in LADDERS if l.name in only or l.name.split()[0] in only
                    or ("unseen" in only and "(unseen" in l.name))
    return ladders, FALSE_FINDINGS in only


def main() -> None:
    """Run both studies (or those --only names) and print the detection table, the limits and the false-finding rate."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="half the magnitudes, one seed, 4 + 2 batch and 1 + 1 driver correct runs")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per magnitude (default 3; --quick: 1)")
    parser.add_argument("--only", nargs="+", metavar="NAME",
                        help=f"only these ladders (name, first word, or 'unseen') and/or '{FALSE_FINDINGS}'")
    args = parser.parse_args()
    ladders, with_false = selected(args.only)
    seeds = args.seeds or (1 if args.quick else 3)
    start, load_start = time.perf_counter(), os.getloadavg()[0]
    print(f"detection vs magnitude: {seeds} seed(s) per cell from {LADDER_SEED}, 1 h Table 1 runs", flush=True)
    study = ladder_study(ladders, seeds, args.quick)
    false: list[tuple[str, Case]] = []
    if with_false:
        print("false findings", flush=True)
        false = false_study(*(QUICK_RUNS if args.quick else (CORRECT_RUNS, LINEAR_RUNS, DRIVER_RUNS)))

    if study:
        print("\n| effect | magnitude | baseline/floor | named | wrong | nothing | mean abs(gain - truth) pts "
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
    if false:
        print()
        for group in dict.fromkeys(g for g, _ in false):
            print(false_rate(f"false findings, {group}", [c for g, c in false if g == group]))
        print(false_rate("false findings, all", [c for _, c in false]))
    total = time.perf_counter() - start
    diagnosing = (sum(c.seconds for cells in study for cell in cells for c in cell.cases)
                  + sum(c.seconds for _, c in false))
    print(f"wall time {total:.0f} s ({total / 60:.1f} min), diagnose alone {diagnosing:.0f} s; "
          f"load average {load_start:.2f} at the start, {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
