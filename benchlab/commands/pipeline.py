"""`benchlab pipeline --out DIR`: the whole job on the simulated bench, end to end.

Runs Table 1 on the simulated bench (plus a validation draw with another seed), identifies the
linear and the nonlinear model, diagnoses the linear baseline, and estimates wear.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchlab.commands.diagnose import print_report
from benchlab.diagnose import diagnose
from benchlab.identify.api import identify
from benchlab.params import load_params, save_params
from benchlab.runfile import load_run, write_run
from benchlab.wear import analyse_wear
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

NAME = "pipeline"
HELP = "run Table 1 on the simulated bench, identify, diagnose, estimate wear: the main job"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out", help="directory for run, parameter and report files")
    parser.add_argument("--seed", type=int, default=1, help="seed of the schedule and the bench's noise")
    parser.add_argument("--duration", type=float, default=3600.0, help="planned protocol duration in s")


def _bench_run(path: Path, seed: int, duration: float, protocol: str):
    frame = run_schedule(table1_schedule(seed, duration_s=duration), ThermalPlant(), seed=seed)
    write_run(path, frame, frame.attrs["dt"], protocol=protocol)
    run = load_run(path)
    print(f"run       {path}: {len(run)} samples, {run['time'].iloc[-1] / 3600:.2f} h")
    return run


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fitting = _bench_run(out / "table1.h5", args.seed, args.duration, "table1")
    validation = _bench_run(out / "validation.h5", args.seed + 1000, args.duration / 2, "validation")
    for model in ("linear", "nonlinear"):
        result = identify([fitting], model, validate=[validation], starts=4)
        save_params(out / f"{model}.json", result.params, result.summary())
        fit_fig, val_fig = next(iter(result.fitting.values())), next(iter(result.validation.values()))
        print(f"identify  {model:9s}: fit RMSE {fit_fig['rmse_K']:.3f} K ({fit_fig['nrmse_pct']:.2f} %), "
              f"validation RMSE {val_fig['rmse_K']:.3f} K ({val_fig['nrmse_pct']:.2f} %) -> {out / (model + '.json')}")
    report = diagnose([fitting], baseline="linear")
    (out / "diagnose.json").write_text(json.dumps(report, indent=2, default=float))
    print_report(report)
    wear = analyse_wear(fitting, load_params(out / "nonlinear.json")).as_dict()
    (out / "wear.json").write_text(json.dumps(wear, indent=2, default=float))
    print(f"wear      {wear['engagements']} engagements, {wear['friction_energy_J'] / 1e6:.2f} MJ -> {out / 'wear.json'}")
    return 0
