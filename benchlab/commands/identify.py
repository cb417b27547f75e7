"""`benchlab identify RUN.h5 [RUN2.h5 …] --model FILE.toml|linear|nonlinear --out P.json [--validate V.h5 …]`."""

from __future__ import annotations

import argparse

from benchlab import cliargs
from benchlab.bounds import MAX_FIT_STARTS, MAX_FIT_STEP_S
from benchlab.errors import InputError
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.interrupts import interrupts_held
from benchlab.model.names import MODEL_HELP
from benchlab.outputs import check_output
from benchlab.progress import for_terminal

NAME = "identify"
HELP = "grey-box identification of a thermal model (the clutch's or a model file's) from one or more run files"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", help="run files to fit together")
    parser.add_argument("--model", default="nonlinear", help=f"{MODEL_HELP} (default nonlinear)")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="parameter file to write (JSON)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file (never a run file)")
    parser.add_argument("--validate", action="append", default=[], metavar="V.h5",
                        help="a run file to validate on (not fitted); repeat for more")
    parser.add_argument("--fix", type=cliargs.name_values, action="extend", default=[], metavar="NAME=VALUE[,...]",
                        help="hold parameters fixed; repeat or separate by commas")
    parser.add_argument("--starts", type=cliargs.count("a number of starting points", MAX_FIT_STARTS), default=6,
                        help="number of starting points (local minima exist)")
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="seed of the starting points")
    parser.add_argument("--step", type=cliargs.positive_float("a fitting step in s", MAX_FIT_STEP_S),
                        default=FIT_STEP_S, help=f"fitting step in s: inputs averaged over it (default {FIT_STEP_S:g}; "
                                                 "slow machines sampled at 1 s fit as well at a few seconds)")


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.identify.api import identify, parse_fixed
        from benchlab.identify.identifiability import not_identified_lines
        from benchlab.model.catalog import model_spec, resolve_model
        from benchlab.model.runs import load_runs
        from benchlab.model.params import save_params
    check_output(args.out, "--out", args.force, inputs=[*args.runs, *args.validate])
    try:
        fixed = parse_fixed(args.fix)
    except ValueError as exc:
        raise InputError("--fix", str(exc).split(":")[0].removeprefix("--fix "), "NAME=NUMBER") from None
    model = resolve_model(args.model)
    known = {p.name: p for p in model_spec(model).free}
    for name, value in fixed.items():
        if name not in known:
            raise InputError("--fix", name, f"a free parameter of the {model.label} model ({', '.join(sorted(known))})")
        spec = known[name]
        if not spec.lower <= value <= spec.upper:
            raise InputError("--fix", name, f"a value in [{spec.lower:g}, {spec.upper:g}] {spec.unit}, got {value:g}")
    runs = load_runs(args.runs, model)
    validate = load_runs(args.validate, model)
    result = identify(runs, model, fixed, validate, starts=args.starts, seed=args.seed, step_s=args.step,
                      progress=for_terminal(args.quiet))
    save_params(args.out, result.params, result.summary())
    se, unidentified = result.uncertainty.standard_errors, result.uncertainty.not_identified
    print(f"{args.out}: {model.label} model from {len(runs)} run(s), {result.fit.starts} starts")
    for name, why in unidentified.items():
        print(f"  {name:7s} = {result.params[name]:12.6g}   not identified: {why}")
    for name, value in result.params.items():
        if name in se and name not in unidentified:
            print(f"  {name:7s} = {value:12.6g} ± {se[name]:.3g}")
    for path, states in result.initial_states.items():
        fitted = ", ".join(f"{s} {v['value']:.2f}" for s, v in states.items())
        print(f"  initial    {path}: {fitted} degC (fitted start values)")
    for label, group in (("fit", result.fitting), ("validation", result.validation)):
        for path, figures in group.items():
            print(f"  {label:10s} {path}: RMSE {figures['rmse_K']:.3f} K, NRMSE {figures['nrmse_pct']:.2f} %")
    for path, channels in result.residuals.items():
        for channel, tests in channels.items():
            signal, corr = max(tests["input_correlation"].items(), key=lambda item: abs(item[1]), default=("-", 0.0))
            print(f"  residuals  {path} {channel}: {whiteness_verdict(tests)}; "
                  f"{tests['whiteness_outside_pct']:.0f} % of 1-step lags outside, lag-1 autocorrelation "
                  f"{tests['autocorrelation'][1]:+.2f}, strongest input correlation {signal} {corr:+.2f}")
    said = set(not_identified_lines(unidentified))  # printed above, with the parameters
    for warning in result.uncertainty.warnings:
        if warning not in said:
            print(f"  warning: {warning}")
    return 0


def whiteness_verdict(tests: dict) -> str:
    """The residual verdict of residuals.residual_tests in words that name what decided it: not white only when a
    test rejects at alpha/2 (Ljung-Box or the excess over the white noise) and the structure exceeds the limit."""
    level = tests["alpha"] / 2
    rejecting = [f"{name} p {_p_value(p)}" for name, p in (("Ljung-Box", tests["ljung_box_p"]),
                                                           ("excess over white noise", tests["excess_p"]))
                 if p is not None and p < level]
    structure = (f"structure {tests['structure_K']:.3f} K, limit {tests['effect_threshold_K']:.2f} K "
                 f"on {tests['decimation_s']:.0f} s means")
    if tests["white"]:
        return (f"white ({structure}; Ljung-Box p {_p_value(tests['ljung_box_p'])}, excess over white noise p "
                f"{_p_value(tests['excess_p'])}, whiteness rejected below p {level:g})")
    because = ", ".join(rejecting) if rejecting else "too few windows for a test"
    return f"not white ({structure}; rejected by {because}, below p {level:g})"


def _p_value(p: float | None) -> str:
    """A p-value to three decimals ("<0.001" below), or "—" where there were too few samples for the test."""
    return "—" if p is None else "<0.001" if p < 0.0005 else f"{p:.3f}"
