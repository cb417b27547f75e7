"""Coverage study: do identify's 95 % intervals hold the simulated plant's truth, and do batch trends stay quiet?

    nice .venv/bin/python benchmarks/coverage_study.py [--seeds 30] [--minutes 20] [--source virtual|drivers|both]
        [--records coverage.jsonl] [--drift-runs 12]

Per seed and source (the simulated bench through the drivers, `benchlab.runner.session.execute`; or the same
plant batch-simulated, `sim_bench.virtual_run.run_schedule`), a Table 1 run of each clutch model's own plant
(the paper's nonlinear clutch; the linear one, a1 = a2 = 0) is identified with that model. Per parameter: the
share of runs whose interval (estimate ± 1.96 SE) holds the truth, the spread of the estimates over the median
SE (near 1 when the SEs are honest), and the bias in % and in median SEs. Residual tests: the share of runs
that pass every channel with the true structure, and the share in which the linear model fails the nonlinear
plant. Each fit's record is appended to
`--records` (JSON lines), so the figures can be recomputed without fitting again (`--from-records`).

Trends: batches of `--batch` runs drawn from the identical plants' fits (random orders, 2000 draws) give the
share of batches `benchlab.batch.trends` flags (its false-alarm rate, nominal trends.FALSE_ALARM_RATE); a batch
of `--drift-runs` virtual runs whose R0 grows by `--drift-pct` per run gives what it flags then.
Exit 1 if a parameter's coverage is below 90 % or the measured false-alarm rate exceeds twice the nominal.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from benchlab.batch import trends
from benchlab.identify.api import Identification, identify
from benchlab.model.params import paper_params
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from protocols.table1 import table1_schedule
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

Z95 = 1.959964
NOMINAL = 0.95
MIN_COVERAGE = 0.90
MODELS = ("nonlinear", "linear")
PLANT = "paper"  # every run here is of paper_plant: the records say so


def paper_plant(params: dict) -> ThermalPlant:
    """The paper's network with `params` and no extra effects: the plant the clutch models can match exactly, so
    every deviation from its truth is estimation error (a richer plant would add model-structure error)."""
    return ThermalPlant(params, effects=())


def simulated_run(source: str, model: str, seed: int, minutes: float, params: dict | None = None) -> pd.DataFrame:
    """A Table 1 run of `model`'s paper plant (or of `params`) through the drivers or batch-simulated."""
    plant = paper_plant(params or paper_params(model))
    if source == "virtual":
        return run_schedule(table1_schedule(seed, duration_s=60 * minutes), plant, seed=seed)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.h5"
        execute(RunRequest("table1", path, bench=SimulatedBench(plant=plant), seed=seed, duration_s=60 * minutes,
                           install_signals=False))
        return load_run(path)


def residual_verdicts(result: Identification) -> dict:
    """Per measured channel of the one run: white, input-correlated, structure (K)."""
    tests = next(iter(result.residuals.values()))
    return {c: {"white": t["white"], "input_correlated": t["input_correlated"], "structure_K": t["structure_K"]}
            for c, t in tests.items()}


def record(source: str, model: str, seed: int, run: pd.DataFrame, truth: dict, starts: int) -> dict:
    """One fit: estimates, reported SEs, their method, the truth, the residual verdicts; on the nonlinear plant
    also the linear model's verdicts (model-structure error the tests must catch)."""
    result = identify([run], model, starts=starts, seed=0)
    se = result.uncertainty.standard_errors
    names = [k for k in result.params if k in se and "@" not in k]
    wrong = residual_verdicts(identify([run], "linear", starts=starts, seed=0)) if model == "nonlinear" else None
    return {"source": source, "model": model, "plant": PLANT, "seed": seed, "truth": {k: truth[k] for k in names},
            "estimate": {k: result.params[k] for k in names}, "se": {k: se[k] for k in names},
            "method": result.summary()["uncertainty_method"]["name"], "residuals": residual_verdicts(result),
            "wrong_model_residuals": wrong}


def residual_rates(records: list[dict]) -> pd.DataFrame:
    """Per source and model: share of runs whose residual tests pass every channel on the true structure, and
    share in which the linear model on the nonlinear plant fails at least one."""
    rows = []
    for (source, model), group in pd.DataFrame(records).groupby(["source", "model"]):
        passed = [all(t["white"] and not t["input_correlated"] for t in r.values()) for r in group["residuals"]]
        wrong = [r for r in group["wrong_model_residuals"] if isinstance(r, dict)]
        caught = [not all(t["white"] and not t["input_correlated"] for t in r.values()) for r in wrong]
        rows.append({"source": source, "model": model, "runs": len(passed), "true_structure_pass_pct":
                     100 * np.mean(passed), "linear_on_nonlinear_fail_pct": 100 * np.mean(caught) if caught else np.nan})
    return pd.DataFrame(rows)


def coverage_table(records: list[dict]) -> pd.DataFrame:
    """Per source, model and parameter: runs, coverage of the 95 % interval, spread / median SE, bias."""
    rows = []
    frame = pd.DataFrame(records)
    for (source, model), group in frame.groupby(["source", "model"]):
        for name in group.iloc[0]["truth"]:
            est = np.array([r[name] for r in group["estimate"]])
            se = np.array([r[name] for r in group["se"]])
            truth = group.iloc[0]["truth"][name]
            z = (est - truth) / se
            held = int(np.sum(np.abs(z) <= Z95))
            low, high = clopper_pearson(held, len(est))
            rows.append({"source": source, "model": model, "param": name, "runs": len(est),
                         "coverage_pct": 100 * held / len(est), "ci_low_pct": 100 * low, "ci_high_pct": 100 * high,
                         "p_vs_95": stats.binomtest(held, len(est), NOMINAL).pvalue,
                         "z_mean": np.mean(z), "z_sd": np.std(z, ddof=1),
                         "spread_over_se": np.std(est, ddof=1) / np.median(se),
                         "bias_pct": 100 * (np.mean(est) - truth) / abs(truth),
                         "bias_over_se": (np.mean(est) - truth) / np.median(se)})
    return pd.DataFrame(rows)


def clopper_pearson(held: int, runs: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) confidence interval of a coverage measured as `held` of `runs`."""
    alpha = 1 - level
    low = stats.beta.ppf(alpha / 2, held, runs - held + 1) if held else 0.0
    high = stats.beta.ppf(1 - alpha / 2, held + 1, runs - held) if held < runs else 1.0
    return float(low), float(high)


def chance_below(runs: int, cells: int, threshold: float = MIN_COVERAGE) -> tuple[float, float]:
    """If every interval held the truth at exactly the nominal 95 %: the chance that one parameter's measured
    coverage over `runs` falls below `threshold`, and that at least one of `cells` such coverages does."""
    misses_allowed = int(np.floor(runs * (1 - threshold) + 1e-9))
    one = float(stats.binom.sf(misses_allowed, runs, 1 - NOMINAL))
    return one, 1 - (1 - one) ** cells


def batch_table(values: Iterable[dict], ses: Iterable[dict]) -> pd.DataFrame:
    """A batch table as `benchlab batch identify` writes it (no creation times: run index axis)."""
    rows = [{"index": i, "status": trends.OK, **v, **{f"{k}{trends.SE_SUFFIX}": s[k] for k in s}}
            for i, (v, s) in enumerate(zip(values, ses))]
    return pd.DataFrame(rows)


def false_alarm_rate(records: list[dict], batch: int, draws: int = 2000, seed: int = 0) -> float:
    """Share of batches of `batch` runs of identical plants (random orders) in which trends flags any column."""
    rng = np.random.default_rng(seed)
    flagged = 0
    for _ in range(draws):
        pick = rng.choice(len(records), size=batch, replace=False)
        table = batch_table([records[i]["estimate"] for i in pick], [records[i]["se"] for i in pick])
        flagged += bool(trends.trend_table(table, list(records[0]["estimate"]))["drifting"].any())
    return flagged / draws


def drift_batch(runs: int, pct: float, minutes: float, starts: int) -> pd.DataFrame:
    """Trends of a batch of virtual runs of the nonlinear plant whose R0 grows by `pct` % per run."""
    values, ses = [], []
    for i in range(runs):
        truth = dict(paper_params("nonlinear")) | {"R0": 0.15 * (1 + pct / 100) ** i}
        rec = record("virtual", "nonlinear", 500 + i, simulated_run("virtual", "nonlinear", 500 + i, minutes, truth),
                     truth, starts)
        values.append(rec["estimate"])
        ses.append(rec["se"])
    return trends.trend_table(batch_table(values, ses), list(values[0]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--starts", type=int, default=4)
    parser.add_argument("--source", choices=["virtual", "drivers", "both"], default="both")
    parser.add_argument("--records", type=Path, default=Path("coverage.jsonl"))
    parser.add_argument("--from-records", action="store_true", help="no fits: figures from --records")
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--drift-runs", type=int, default=0)
    parser.add_argument("--drift-pct", type=float, default=3.0)
    args = parser.parse_args()
    sources = ["virtual", "drivers"] if args.source == "both" else [args.source]
    if not args.from_records:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for source in sources:
                for model in MODELS:
                    rec = record(source, model, seed, simulated_run(source, model, seed, args.minutes),
                                 paper_params(model), args.starts)
                    with args.records.open("a") as f:
                        f.write(json.dumps(rec) + "\n")
                    print(f"seed {seed} {source} {model}: max |z| "
                          f"{max(abs(rec['estimate'][k] - rec['truth'][k]) / rec['se'][k] for k in rec['se']):.2f}",
                          flush=True)
    records = [json.loads(line) for line in args.records.read_text().splitlines() if line.strip()]
    table = coverage_table(records)
    pd.set_option("display.width", 160)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    if all("residuals" in r for r in records):
        print("\nresidual tests:\n" + residual_rates(records).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    methods = sorted({r["method"] for r in records})
    print(f"\ninterval methods in these records: {methods}")
    low = table[table["coverage_pct"] < 100 * MIN_COVERAGE]
    one, any_cell = chance_below(int(table["runs"].min()), len(table))
    rejected = table[table["p_vs_95"] < 0.01 / len(table)]
    print(f"if every interval were exactly 95 %: a coverage over {int(table['runs'].min())} runs falls below "
          f"{100 * MIN_COVERAGE:.0f} % by chance with p = {one:.3f}, at least one of these {len(table)} with "
          f"p = {any_cell:.2f}")
    print("coverage inconsistent with 95 % (binomial, 1 % Bonferroni over the table): "
          f"{'none' if rejected.empty else ', '.join(f'{r.source}/{r.model}/{r.param}' for r in rejected.itertuples())}")
    for (source, model), group in table.groupby(["source", "model"]):
        print(f"pooled coverage {source}/{model}: {np.average(group['coverage_pct'], weights=group['runs']):.1f} % "
              f"over {len(group)} parameters")
    print(f"coverage below {100 * MIN_COVERAGE:.0f} %: "
          f"{'none' if low.empty else ', '.join(f'{r.source}/{r.model}/{r.param}' for r in low.itertuples())}")
    rates = {}
    for (source, model), group in pd.DataFrame(records).groupby(["source", "model"]):
        if len(group) >= args.batch:
            rates[(source, model)] = false_alarm_rate(group.to_dict("records"), args.batch)
            print(f"trends false-alarm rate, {source}/{model}, batches of {args.batch} identical plants: "
                  f"{100 * rates[(source, model)]:.1f} % (nominal {100 * trends.FALSE_ALARM_RATE:.0f} %)")
    if args.drift_runs:
        drift = drift_batch(args.drift_runs, args.drift_pct, args.minutes, args.starts)
        print(f"\nR0 drifting {args.drift_pct:g} % per run over {args.drift_runs} runs: flagged "
              f"{list(drift.loc[drift['drifting'], 'column'])}; R0 p = {drift.set_index('column').loc['R0', 'p_value']:.2g}")
    too_many = any(rate > 2 * trends.FALSE_ALARM_RATE for rate in rates.values())
    return 1 if not low.empty or too_many else 0


if __name__ == "__main__":
    sys.exit(main())
