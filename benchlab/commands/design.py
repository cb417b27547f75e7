"""`benchlab design RUN.h5 [RUN2.h5 …] --params P.json | --diagnosis D.json --out PLAN.json [--budget MINUTES]
[--bench sim|BENCH.toml]`: the next run, chosen to identify what the runs leave open or to tell apart the models a
diagnosis leaves tied (docs/design.md); `benchlab run PLAN.json` runs it."""

from __future__ import annotations

import argparse
from pathlib import Path

from benchlab import cliargs
from benchlab.bounds import MAX_RUN_DURATION_S
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.outputs import check_output

NAME = "design"
HELP = ("design the next run: launches and cool-downs that identify the parameters a parameter file leaves open, "
        "or tell apart the models a diagnosis leaves tied")
#: The plan file's schema (docs/contract.md §3, "Plan file").
PLAN_SCHEMA = "benchlab-plan/1"
DEFAULT_BUDGET_MIN = 30.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", metavar="RUN.h5", help="the runs so far (those the parameter file was "
                                                                   "identified on)")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--params", help="parameter file of `benchlab identify` on those runs: its "
                        "not_identified parameters are designed for, the others are nuisance")
    source.add_argument("--diagnosis", metavar="D.json", help="diagnose JSON of those runs: the run that best tells "
                        "apart its tied alternatives (or its first finding and the model without it), each refitted")
    parser.add_argument("--parameters", metavar="NAME,…", help="design for these free parameters (default: those the "
                        "parameter file records as not identified); the others are nuisance")
    parser.add_argument("--reading", action="store_true", help="design for reading the run's cool-downs one by "
                        "one, eq. (11) fitted to their points (`benchlab cooldown`), instead of the joint fit with the "
                        "runs so far: eq. (11)'s parameters only (docs/design.md)")
    parser.add_argument("--out", required=True, type=cliargs.output_file, metavar="PLAN.json",
                        help="the plan: a schedule `benchlab run PLAN.json --bench …` runs, and the expected outcome")
    parser.add_argument("--budget", type=cliargs.positive_float("a duration in min", MAX_RUN_DURATION_S / 60),
                        default=DEFAULT_BUDGET_MIN, metavar="MINUTES",
                        help=f"the designed run's planned length (default {DEFAULT_BUDGET_MIN:g} min)")
    parser.add_argument("--bench", default="sim", help="the bench whose limits and drivetrain the plan keeps: 'sim' "
                                                       "(default) or a BENCH.toml")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")


def run(args: argparse.Namespace) -> int:
    check_output(Path(args.out), "--out", args.force, inputs=[args.params or args.diagnosis, *args.runs])
    with interrupts_held():  # the implementation's imports (see benchlab.cli)
        from benchlab.design.command import design, discriminate

    return discriminate(args, PLAN_SCHEMA) if args.diagnosis else design(args, PLAN_SCHEMA)
