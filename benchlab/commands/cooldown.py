"""`benchlab cooldown RUN.h5 --params P.json [--out ANALYSIS.h5 | --store]`: convection resistance per cool-down and
the fit of eq. (11), printed; stored as /analysis in a file of its own (`--out`) or, asked explicitly, in the run
file (`--store`). The run file is never modified otherwise (benchlab.outputs)."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict
from pathlib import Path

from benchlab import cliargs
from benchlab.bounds import MAX_SAMPLE_PERIOD_S
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.outputs import check_output


NAME = "cooldown"
HELP = "fit R_FA = R_PA for every cool-down of a cooldown-sweep run, then eq. (11); /analysis to --out or --store"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file of a cooldown-sweep")
    parser.add_argument("--params", required=True,
                        help="parameter file (identified from a Table 1 run) for every parameter but R; "
                             "'sim-truth' uses the simulated bench's true parameters stored in the run")
    parser.add_argument("--sample", type=cliargs.positive_float("a sampling period in s", MAX_SAMPLE_PERIOD_S),
                        default=1.0, help="residual sampling period in s (default 1)")
    parser.add_argument("--json", action="store_true", help="print the table and eq. (11) as JSON")
    parser.add_argument("--out", type=cliargs.output_file, metavar="ANALYSIS.h5",
                        help="write /analysis into this file of its own (`benchlab report --sweep` reads it)")
    parser.add_argument("--store", action="store_true",
                        help="write /analysis into the run file itself (rebuilt beside it and renamed into place)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file (never a run file)")
    parser.add_argument("--no-store", action="store_true",
                        help="nothing is written into the run file (the default since --store; kept for scripts)")


def load_analysis_params(spec: str, run: Path) -> "dict[str, float]":
    """The parameters every segment's fit holds: a parameter file (ModelParams, with its model) or the simulated
    paper plant's truth."""
    if spec == "sim-truth":
        from benchlab.runfile import load_attrs

        truth = load_attrs(run).get("sim_truth")
        if truth is None:
            raise InputError(run, "sim_truth", "a run of the simulated bench for --params sim-truth")
        recorded = json.loads(truth)
        if recorded.get("plant", "paper") != "paper":
            raise InputError(run, "sim_truth", "a run of the paper plant (--plant paper) for --params sim-truth: the "
                                               f"{recorded['plant']} plant has no parameters of the model")
        return dict(recorded["params"])
    from benchlab.model.catalog import builtin
    from benchlab.model.params import load_params

    params = load_params(spec)
    missing = [name for name in builtin("linear").parameters if name != "R0" and name not in params]
    if missing:
        raise InputError(spec, f"params.{missing[0]}", "a clutch model's parameters (the cool-downs are fitted with "
                                                        "the linear clutch model file, R0 free)")
    return params


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.identify.cooldown import analyse, fit_eq11, segment_model, store, table_lines
        from benchlab.progress import for_terminal
        from benchlab.runfile import load_run

    path = Path(args.run)
    if args.store and (args.out or args.no_store):
        raise InputError("command line", "--store", "--out ANALYSIS.h5 or --store, not both (and not --no-store)")
    if args.out:
        check_output(args.out, "--out", args.force, inputs=[path, args.params])
    load_run(path)  # checks the file (InputError on a bad one)
    params = load_analysis_params(args.params, path)
    results = analyse(path, params, args.sample, progress=for_terminal(args.quiet), model=segment_model(params))
    try:
        eq11 = fit_eq11(results, partial=True)  # a designed run's cool-downs may cover one clutch state
    except ValueError:
        eq11 = None
    if args.store or args.out:
        store(path, results, eq11, args.params, out=args.out)
    if args.json:
        clean = lambda v: None if isinstance(v, float) and not math.isfinite(v) else v  # noqa: E731
        print(json.dumps({"cooldowns": [{k: clean(v) for k, v in asdict(r).items()} for r in results],
                          "eq11": {k: clean(v) for k, v in eq11.items()} if eq11 else None}, indent=1))
    else:
        print("\n".join(table_lines(results, eq11)))
        if eq11 is None:
            print("eq. (11): not enough points (needs 5 cool-downs, 2 engine speeds per clutch state, or 3 in one)")
    return 0
