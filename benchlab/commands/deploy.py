"""`benchlab deploy P.json --out DIR [--model M] [--sensors T_air] [--step S] [--double] [--clutch FILE]
[--verify RUN.h5 ...] [--json]`: the model, its observer and the wear as a C99 module, proven against benchlab's
observer on run files (docs/deploy.md)."""

from __future__ import annotations

import argparse
import json

from benchlab import cliargs
from benchlab.commands.observe import _sensors
from benchlab.interrupts import interrupts_held
from benchlab.model.options import add_model_option, load_model_params
from benchlab.outputs import check_output_dir

NAME = "deploy"
HELP = "the model's observer and wear as a C99 module for a control unit, proven on run files (--verify)"
#: Longest sample time the module takes (s): a control unit's slow task, not a cool-down.
MAX_STEP_S = 10.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("params", help="parameter file (JSON)")
    add_model_option(parser)
    parser.add_argument("--out", required=True, help="directory for <name>.h, <name>.c, README.md (and verify.json)")
    parser.add_argument("--sensors", type=_sensors, default=["T_air"],
                        help="measured channels the module reads, comma-separated (default T_air, the paper's extra "
                             "sensor; 'none' for the model alone)")
    parser.add_argument("--step", type=cliargs.positive_float("a sample time in s", MAX_STEP_S), default=0.01,
                        metavar="S", help="the task's sample time in s")
    parser.add_argument("--double", action="store_true", help="double precision (default: float, a TCU's FPU)")
    parser.add_argument("--clutch", help="clutch file (TOML) for the wear; default: documented assumptions")
    parser.add_argument("--verify", nargs="+", default=[], metavar="RUN.h5",
                        help="compile with cc and run the module over these run files beside benchlab's observer")
    parser.add_argument("--json", action="store_true", help="print one JSON object (docs/contract.md)")
    parser.add_argument("--force", action="store_true", help="write into a directory that holds files")


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli)
        from pathlib import Path

        from benchlab.deploy.module import prove, write_module
        from benchlab.deploy.plan import make_plan
        from benchlab.deploy.verify import compiler
        from benchlab.model.runs import load_runs
        from benchlab.outputs import write_text
        from benchlab.wear.clutchfile import default_clutch, load_clutch
    out = check_output_dir(args.out, "--out", args.force)
    real = "double" if args.double else "float"
    params = load_model_params(args.params, args.model)
    clutch = load_clutch(args.clutch) if args.clutch else default_clutch()
    plan = make_plan(params, args.sensors, args.step, clutch)
    proof = None
    if args.verify:
        compiler()  # before the runs are read: no compiler is one line, at once
        runs = load_runs(args.verify, params.definition, params, args.params)
        proof = prove(plan, runs, real)
    written = write_module(out, plan, real, proof)
    if proof is not None:
        written.append(write_text(Path(out) / "verify.json", json.dumps(proof, indent=1) + "\n"))
    if args.json:
        print(json.dumps({"module": plan.name, "files": [str(p) for p in written], **(proof or {})}))
        return 0
    print(f"{out}: {plan.name} ({real}, {plan.dt:g} s, {len(plan.states)} states, inputs "
          f"{', '.join(plan.inputs)}; sensors {', '.join(plan.sensors) or 'none'})")
    if proof is not None:
        for channel, dev in proof["max_abs_dev_K"].items():
            print(f"  {channel:18s} largest deviation {dev:.3g} K, σ {proof['sigma_rel_dev'][channel]:.3g} relative")
        if proof["wear_rel_dev"] is not None:
            print(f"  wear relative deviation {proof['wear_rel_dev']:.3g}")
        print(f"  state {proof['state_bytes']} bytes, code {proof['code_bytes']} bytes, {proof['step_us']:.3g} µs "
              f"per step ({proof['budget_us']:.0f} µs budget); proof in {Path(out) / 'verify.json'}")
    return 0
