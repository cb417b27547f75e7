"""`benchlab simulate RUN.h5 --params P.json [--model FILE.toml|linear|nonlinear] --out SIM.h5`: SIM.h5 is the run
file plus /simulated."""

from __future__ import annotations

import argparse

from benchlab import cliargs
from benchlab.interrupts import interrupts_held
from benchlab.model.options import add_model_option, load_model_params
from benchlab.outputs import check_output

NAME = "simulate"
HELP = "drive the model with a run's measured inputs and write /simulated"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--params", required=True, help="parameter file (JSON)")
    add_model_option(parser)
    parser.add_argument("--out", required=True, type=cliargs.output_file,
                        help="file to write: the run's root attributes and /aligned plus /simulated (a run file)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file (never the run it reads)")


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.identify.metrics import nrmse_pct, rmse_k
        from benchlab.model.runs import load_runs
        from benchlab.runfile import write_beside_run
        from benchlab.network.simulation import simulate
    check_output(args.out, "--out", args.force, inputs=[args.run, args.params], run_file=True)
    params = load_model_params(args.params, args.model)
    measured = load_runs([args.run], params.definition, params, args.params, model_channels_only=True)[0]
    simulated = simulate(measured, params)
    write_beside_run(args.out, args.run, "simulated", measured["time"].to_numpy(),
                     {name: (simulated[name].to_numpy(), "degC", f"model {params.model}: {name} driven by the run's "
                                                                 "measured inputs") for name in simulated.columns},
                     {"source_run": str(args.run), "params": str(args.params), "model": params.model})
    scored = [c for c in params.network.measured if c in measured.columns]
    print(f"{args.out}: {len(simulated)} samples, {params.model} model, "
          f"RMSE {rmse_k(measured, simulated, scored):.3f} K, NRMSE {nrmse_pct(measured, simulated, scored):.2f} %")
    return 0
