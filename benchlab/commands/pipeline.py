"""`benchlab pipeline --out DIR`: the whole job on the simulated bench, end to end (always the simulated bench, by
design: it is the demonstration and the check that everything fits together; each line and page says so).

Runs Table 1 on the simulated bench and the validation protocol (long hot cool-downs with the engine
speed or the clutch state changing, then a few fresh Table 1 cycles), identifies the linear and the
nonlinear model, writes the report (Fig. 3, 4, 5, residuals: nonlinear against linear, validated on the
validation run), diagnoses the linear baseline with its page, and estimates wear.

Both runs go through the bench runner (benchlab.runner) and the real drivers talking to the simulated
bench's devices, as on hardware: every reading at the time it was measured, a raw CAN log (BLF) beside
each run file, the validation's heat-ups closed loop ("heat until the flywheel is at 70 °C").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.bounds import MAX_RUN_DURATION_S
from benchlab.interrupts import interrupts_held
from benchlab.outputs import check_output_dir, write_text
from benchlab.progress import Progress, for_terminal
from benchlab.provenance import bench_text

if TYPE_CHECKING:
    import pandas as pd

NAME = "pipeline"
HELP = "run Table 1 and the validation protocol on the simulated bench, identify, report, diagnose, estimate wear"
VALIDATION_CYCLES = 3  # Table 1 cycles after the validation protocol's three long cool-downs


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out", help="directory for run, parameter and report files")
    parser.add_argument("--seed", type=cliargs.seed, default=1, help="seed of the schedule and the bench's noise")
    parser.add_argument("--duration", type=cliargs.positive_float("a duration in s", MAX_RUN_DURATION_S),
                        default=3600.0, help="planned Table 1 duration in s")
    parser.add_argument("--force", action="store_true", help="--out may hold files already (an earlier job's): "
                                                             "replace the ones the job writes")


def _describe(label: str, path: Path, run: pd.DataFrame) -> None:
    print(f"{label:<9} {path}: {len(run)} samples, {run['time'].iloc[-1] / 3600:.2f} h, "
          f"flywheel up to {run['T_flywheel'].max():.1f} degC, on {bench_text(run.attrs.get('bench'))}")


def _bench_run(label: str, path: Path, protocol: str, seed: int, progress: Progress, **options: float) -> pd.DataFrame:
    """One protocol on the simulated bench through the runner and the real drivers; the run as loaded back."""
    with interrupts_held():  # the runner and the simulator (see benchlab.cli)
        from benchlab.runfile import load_run
        from benchlab.runner.session import RunRequest, execute
        from sim_bench.bench import SimulatedBench
        from sim_bench.plant import ThermalPlant

    code, summary = execute(RunRequest(protocol=protocol, out=path, seed=seed, bench=SimulatedBench(ThermalPlant()),
                                       install_signals=False, progress=progress, **options))
    if code != 0 or summary is None or summary.status != "complete":
        raise RuntimeError(f"{label} run {path} ended {summary.status if summary else 'without a summary'} "
                           f"(exit {code})")
    run = load_run(path)
    _describe(label, path, run)
    return run


def _diagnose(fitting: pd.DataFrame, out: Path, progress: Progress) -> dict:
    """Diagnose the linear baseline on the fitting run: JSON, page with figures, two labelled lines; the summary."""
    with interrupts_held():  # the diagnosis and its page (matplotlib; see benchlab.cli)
        from benchlab.diagnose.engine import diagnose_runs
        from benchlab.diagnose.page import write_page
        from benchlab.diagnose.regimes import worst_regimes
        from benchlab.diagnose.report import summarise

    diagnosis = diagnose_runs([fitting], "linear", progress=progress)
    summary = summarise(diagnosis, "linear")
    write_text(out / "diagnose.json", json.dumps(summary, indent=2, default=float))
    page = write_page(diagnosis, summary, [fitting], out / "diagnose").with_suffix(".html")
    base, best = summary["baseline"], summary["best"]
    found = ", ".join(f"{f['candidate']} ({f['signal']}/{f['mechanism']}, gain {f['gain_pct']:.0f} %)"
                      for f in summary["findings"]) or "none"
    print(f"diagnose  linear baseline: held-out RMSE {base['rmse_K']:.3f} K -> best {best['model']} "
          f"{best['rmse_K']:.3f} K; findings: {found}")
    worst = worst_regimes(summary["regimes"]["baseline"], 1)
    if worst:
        group, label, channel, rmse, _ = worst[0]
        print(f"          worst regime (held-out): {group} = {label}, {channel} {rmse:.3f} K -> {page}")
    return summary


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.identify.api import identify
        from benchlab.model.params import load_params, save_params
        from benchlab.report import write_report
        from benchlab.report.index import cooldown_scores, write_index
        from benchlab.report.resistance import standard_errors
        from benchlab.wear import analyse_wear
        from benchlab.wear.plot import plot_wear

    progress = for_terminal(args.quiet)
    out = check_output_dir(args.out, "--out", args.force)
    out.mkdir(exist_ok=True)
    for stale in [out / "table1.h5", out / "validation.h5", *out.glob("table1*.blf"), *out.glob("validation*.blf")]:
        stale.unlink(missing_ok=True)  # the job writes its runs anew each time
    fitting = _bench_run("run", out / "table1.h5", "table1", args.seed, progress, duration_s=args.duration)
    validation = _bench_run("validation", out / "validation.h5", "validation", args.seed + 1, progress,
                            cycles=VALIDATION_CYCLES)
    figures = {}
    for model in ("linear", "nonlinear"):
        result = identify([fitting], model, validate=[validation], starts=4, progress=progress)
        save_params(out / f"{model}.json", result.params, result.summary())
        fit_fig, val_fig = next(iter(result.fitting.values())), next(iter(result.validation.values()))
        figures[model] = {"fit": fit_fig, "validation": val_fig}
        print(f"identify  {model:9s}: fit RMSE {fit_fig['rmse_K']:.3f} K ({fit_fig['nrmse_pct']:.2f} %), "
              f"validation RMSE {val_fig['rmse_K']:.3f} K ({val_fig['nrmse_pct']:.2f} %) -> {out / (model + '.json')}")
    nonlinear, linear = load_params(out / "nonlinear.json"), load_params(out / "linear.json")
    page = write_report(fitting, nonlinear, out / "report", compare=linear, validation=[validation],
                        progress=progress)
    print(f"report    nonlinear against linear, validated on {out / 'validation.h5'} -> {page.with_suffix('.html')}")
    diagnosis = _diagnose(fitting, out, progress)
    wear_report = analyse_wear(fitting, nonlinear)
    wear = wear_report.as_dict()
    write_text(out / "wear.json", json.dumps(wear, indent=2, default=float))
    plot_wear(wear_report, out / "wear.png")
    print(f"wear      {wear['engagements']} engagements, {wear['friction_energy_J'] / 1e6:.2f} MJ -> {out / 'wear.json'}")
    cooldowns = cooldown_scores(validation, out / "validation.h5", [("linear", linear), ("nonlinear", nonlinear)])
    index = write_index(out, {"Table 1": (out / "table1.h5", fitting), "validation": (out / "validation.h5", validation)},
                        figures, cooldowns, nonlinear, standard_errors(nonlinear), diagnosis, wear)
    print(f"page      the whole job -> {index}")
    return 0
