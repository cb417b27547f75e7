"""`benchlab pipeline --out DIR`: the whole job on the simulated bench, end to end."""

from __future__ import annotations

import argparse
from pathlib import Path

from benchlab.metrics import channel_rmse_k, nrmse_pct, rmse_k
from benchlab.params import paper_params, save_params
from benchlab.runfile import load_run, write_run
from benchlab.simulation import simulate
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

NAME = "pipeline"
HELP = "run Table 1 on the simulated bench and model it: the main job, end to end"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out", help="directory for run, parameter and report files")
    parser.add_argument("--seed", type=int, default=1, help="seed of the schedule and the bench's noise")
    parser.add_argument("--duration", type=float, default=7200.0, help="planned protocol duration in s")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frame = run_schedule(table1_schedule(args.seed, duration_s=args.duration), ThermalPlant(), seed=args.seed)
    run_path = out / "table1.h5"
    write_run(run_path, frame, frame.attrs["dt"], protocol="table1")
    measured = load_run(run_path)
    print(f"run      {run_path}: {len(measured)} samples, {measured['time'].iloc[-1] / 3600:.2f} h")
    for model in ("linear", "nonlinear"):
        params = paper_params(model)
        save_params(out / f"paper_{model}.json", params)
        sim = simulate(measured, params)
        per_channel = ", ".join(f"{c} {v:.3f}" for c, v in channel_rmse_k(measured, sim).items())
        print(f"simulate paper {model:9s}: RMSE {rmse_k(measured, sim):.3f} K ({per_channel}), "
              f"NRMSE {nrmse_pct(measured, sim):.2f} %")
    return 0
