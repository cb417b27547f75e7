"""Is the cause diagnose names on the reference plant the same from run to run, and does its gain carry to runs no
fit saw? (issue 41)

    .venv/bin/python benchmarks/stability_diagnose.py [--dir DIR] [--only SEED ...] [--with-sweep]

Per seed N: a Table 1 run of the reference plant (`benchlab run table1 --bench sim --seed N --duration S`, S from
the table below, 1-2 h) and a validation run (`benchlab run validation --bench sim --seed N+1000`), made once into
DIR (default stability-runs/ under the working directory; reused when there) through the runner, the drivers and the emulated devices as a user
makes them. Each Table 1 run is diagnosed with the nonlinear baseline, its validation run unseen
(`diagnose_runs(..., validate=[...])`), one diagnosis at a time; the summary is written to DIR/diagnose_N.json.
With --with-sweep, as the main job does: each seed also gets the Fig. 3 cool-down sweep (`benchlab run cooldown-sweep
--grid SWEEP_GRID --seed N+2000`) and the Table 1 run and the sweep are diagnosed together (DIR/diagnose_sweep_N.json).

Printed per seed: duration, the causes named (each with the alternatives it ties with: `a|b`), the leads with
their unseen gain and reasons, the best model's held-out and unseen gain, and what the engine accepted in-run before
the cause rule (findings and leads together, by round: what diagnose named before issue 41). Then the stability
(answers compared by mechanism: a law's linear and power forms of one dependence are one answer), twice: of the first cause, and of the round-1 extension accepted in-run (with its tie): the largest group of runs
whose answers are joined by shared candidates (a tie shares one with another run's tie, directly or through a third
run's: alternatives the data cannot separate are one answer, not two).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from benchlab.commands.pipeline import SWEEP_GRID
from benchlab.diagnose.engine import diagnose_runs
from benchlab.diagnose.report import summarise
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from sim_bench.bench import SimulatedBench
from sim_bench.reference_plant import plant_named

#: seed -> planned Table 1 duration (s); seeds used by no test (tests use < 1200 and 2001)
RUNS = {4101: 3600.0, 4102: 5400.0, 4103: 7200.0, 4104: 3600.0, 4105: 5400.0, 4106: 7200.0}
VALIDATION_SEED_OFFSET = 1000
SWEEP_SEED_OFFSET = 2000


def bench_run(path: Path, protocol: str, seed: int, **options: object) -> None:
    """One protocol on the simulated reference bench, as `benchlab run PROTOCOL --bench sim` makes it (kept if there)."""
    if path.exists():
        return
    code, summary = execute(RunRequest(protocol=protocol, out=path, seed=seed,
                                       bench=SimulatedBench(plant_named("reference")), install_signals=False,
                                       **options))
    if code != 0 or summary is None or summary.status != "complete":
        raise RuntimeError(f"{path}: run ended with exit {code}")


def mechanism(entry: dict) -> str:
    """What an extension changes, whatever its law's form: `R_AT = R * f(engine_speed)` for both its linear and its
    power form (one physical answer), the extension itself where it has no form."""
    return entry["extension"].split(",")[0]


def tie(finding: dict) -> frozenset[str]:
    """A named extension with the alternatives the data cannot tell from it: one answer."""
    return frozenset([mechanism(finding), *(mechanism(a) for a in finding["alternatives"])])


def described(finding: dict) -> str:
    return "|".join([finding["candidate"], *(a["candidate"] for a in finding["alternatives"])])


def diagnosed(directory: Path, seed: int, duration: float, with_sweep: bool) -> dict:
    """The summary of seed's diagnosis, its validation run unseen (run and diagnosed when not stored yet); with the
    sweep, the Table 1 run and the sweep diagnosed together."""
    out = directory / (f"diagnose_sweep_{seed}.json" if with_sweep else f"diagnose_{seed}.json")
    if out.exists():
        return json.loads(out.read_text())
    table1, validation = directory / f"t1_{seed}.h5", directory / f"val_{seed}.h5"
    bench_run(table1, "table1", seed, duration_s=duration)
    bench_run(validation, "validation", seed + VALIDATION_SEED_OFFSET)
    diagnosed_runs = [table1]
    if with_sweep:
        diagnosed_runs.append(directory / f"sweep_{seed}.h5")
        bench_run(diagnosed_runs[-1], "cooldown-sweep", seed + SWEEP_SEED_OFFSET, grid=SWEEP_GRID)
    started = time.perf_counter()
    result = diagnose_runs([load_run(p) for p in diagnosed_runs], "nonlinear", validate=[load_run(validation)])
    summary = {**summarise(result, "nonlinear"), "diagnose_s": time.perf_counter() - started}
    out.write_text(json.dumps(summary, indent=1, default=float))
    return summary


def first_round(summary: dict) -> dict | None:
    """The extension accepted in round 1 (the baseline's largest error), cause or lead."""
    return next((f for f in summary["findings"] + summary["leads"] if f["round"] == 1), None)


def lead_text(lead: dict) -> str:
    unseen = f"unseen {lead['unseen_gain_pct']:.1f} % p {lead['unseen']['p_value']:.2g}" if lead["unseen"] else ""
    reasons = ", ".join("not identified: " + r.split(" not identified")[0] if " not identified" in r else "no carry"
                        for r in lead["reasons"])
    return f"{lead['candidate']} ({unseen}; {reasons})"


def row(seed: int, summary: dict) -> str:
    causes = "; ".join(f"{described(f)} (unseen {f['unseen_gain_pct']:.1f} %)" for f in summary["findings"]) or "none"
    leads = "; ".join(lead_text(f) for f in summary["leads"]) or "-"
    accepted = "; ".join(f"{f['round']}: {described(f)} {f['gain_pct']:.0f} %"
                         for f in sorted(summary["findings"] + summary["leads"], key=lambda f: f["round"])) or "none"
    base, best = summary["baseline"], summary["best"]
    unseen = best["unseen"]
    return (f"| {seed} | {summary['duration_h']:.2f} | {causes} | {leads} | "
            f"{100 * (1 - best['rmse_K'] / base['rmse_K']):.0f} | {unseen['rmse_before_K']:.3f} -> "
            f"{unseen['rmse_after_K']:.3f} ({unseen['gain_pct']:.0f}) | {accepted} | {summary['diagnose_s']:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", type=Path, default=Path("stability-runs"))
    parser.add_argument("--only", type=int, nargs="*", help="these seeds of RUNS only")
    parser.add_argument("--with-sweep", action="store_true",
                        help="diagnose each Table 1 run together with a cool-down sweep, as the main job does")
    args = parser.parse_args()
    args.dir.mkdir(parents=True, exist_ok=True)
    seeds = args.only or list(RUNS)
    print("| seed | h | causes (ties) | leads (why) | held-out gain % | unseen RMSE K (gain %) | accepted in-run | "
          "diagnose s |\n|---|---|---|---|---|---|---|---|")
    firsts, rounds = {}, {}
    for seed in seeds:
        summary = diagnosed(args.dir, seed, RUNS[seed], args.with_sweep)
        run = load_run(args.dir / f"t1_{seed}.h5", only=("time",))
        summary["duration_h"] = float(run["time"].iloc[-1] - run["time"].iloc[0]) / 3600
        print(row(seed, summary), flush=True)
        firsts[seed] = tie(summary["findings"][0]) if summary["findings"] else frozenset(["none"])
        rounds[seed] = tie(first_round(summary)) if first_round(summary) else frozenset(["none"])
    for what, ties in (("first cause", firsts), ("round-1 extension accepted in-run", rounds)):
        group = largest_group(ties)
        names = sorted(set().union(*(ties[seed] for seed in group)))
        print(f"{what}: {'|'.join(names)} in {len(group)} of {len(ties)} runs ({', '.join(map(str, group))})")


def largest_group(ties: dict[int, frozenset[str]]) -> list[int]:
    """The largest set of runs whose answers are joined by shared candidates (directly or through other runs)."""
    groups: list[tuple[set[int], set[str]]] = []
    for seed, answer in ties.items():
        joined = [g for g in groups if g[1] & answer]
        runs, names = {seed}.union(*(g[0] for g in joined)), set(answer).union(*(g[1] for g in joined))
        groups = [g for g in groups if g not in joined] + [(runs, names)]
    return sorted(max(groups, key=lambda g: len(g[0]))[0])


if __name__ == "__main__":
    main()
