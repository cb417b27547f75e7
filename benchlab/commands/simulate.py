"""`benchlab simulate RUN.h5 --params P.json --out SIM.h5`: SIM.h5 is the run file plus /simulated."""

from __future__ import annotations

import argparse

from benchlab import cliargs
from benchlab.clutch import PREDICTED_CHANNELS
from benchlab.metrics import nrmse_pct, rmse_k
from benchlab.params import load_params
from benchlab.runfile import load_run, write_simulated
from benchlab.simulation import simulate

NAME = "simulate"
HELP = "drive the model with a run's measured inputs and write /simulated"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--params", required=True, help="parameter file (JSON)")
    parser.add_argument("--out", required=True, type=cliargs.output_file,
                        help="file to write: the run's root attributes and /aligned plus /simulated (a run file)")


def run(args: argparse.Namespace) -> int:
    measured = load_run(args.run, measured=PREDICTED_CHANNELS)
    params = load_params(args.params)
    simulated = simulate(measured, params)
    write_simulated(args.out, args.run, simulated,
                    {"source_run": str(args.run), "params": str(args.params), "model": params.model})
    print(f"{args.out}: {len(simulated)} samples, {params.model} model, "
          f"RMSE {rmse_k(measured, simulated):.3f} K, NRMSE {nrmse_pct(measured, simulated):.2f} %")
    return 0
