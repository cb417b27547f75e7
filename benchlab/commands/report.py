"""`benchlab report RUN.h5 --params P.json [--model FILE.toml|linear|nonlinear] --out DIR [--compare P2.json]
[--validate V.h5 …] [--sweep SWEEP.h5]`."""

from __future__ import annotations

import argparse

from benchlab.interrupts import interrupts_held
from benchlab.model.options import add_model_option, load_model_params
from benchlab.outputs import check_output_dir
from benchlab.progress import for_terminal

NAME = "report"
HELP = ("figures of the paper (Fig. 3, 4, 5), residual analysis and a page of error figures: report.md and the same "
        "page as report.html for a browser")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1) the model is shown on (Fig. 4, residuals)")
    parser.add_argument("--params", required=True, help="parameter file (JSON) of the model to report")
    add_model_option(parser)
    parser.add_argument("--out", required=True, help="directory for report.md, report.html and the PNG figures")
    parser.add_argument("--compare", help="second parameter file (typically linear against nonlinear) for Fig. 3 and 5")
    parser.add_argument("--validate", action="append", default=[], metavar="V.h5",
                        help="a validation run file for Fig. 5, repeat for more (default: RUN)")
    parser.add_argument("--sweep", help="cooldown-sweep run file, or the file `benchlab cooldown --out` wrote from "
                                        "one: per-cool-down R with error bars in Fig. 3")
    parser.add_argument("--force", action="store_true", help="--out may hold files already: replace the ones the "
                                                             "report writes (never a run file)")


def sweep_file(path: str) -> None:
    """--sweep: the file `benchlab cooldown --out` wrote, or a run file at all (the events it needs are checked by the
    analysis); InputError otherwise."""
    with interrupts_held():  # see benchlab.cli
        from benchlab.runfile import load_analysis, load_run
    if load_analysis(path) is None:
        load_run(path)


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.model.runs import check_run, load_runs
        from benchlab.model.params import load_params
        from benchlab.report import write_report

    out = check_output_dir(args.out, "--out", args.force)
    params = load_model_params(args.params, args.model)
    compare = load_params(args.compare) if args.compare else None
    measured = load_runs([args.run], params.definition, params, args.params)[0]
    validation = load_runs(args.validate, params.definition, params, args.params)
    if compare is not None:
        for run in [measured, *validation]:
            check_run(compare.definition, run, compare, args.compare)
    if args.sweep:
        sweep_file(args.sweep)
    page = write_report(measured, params, out, compare, validation, args.sweep, progress=for_terminal(args.quiet))
    print(page)
    return 0
