"""`benchlab diagnose RUN.h5 [RUN2.h5 …] [--model FILE.toml|linear|nonlinear] [--validate V.h5 …] [--json]
[--report DIR] [--save-model OUT.toml]`."""

from __future__ import annotations

import argparse
import json
import statistics
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.model.names import MODEL_HELP
from benchlab.outputs import check_output, check_output_dir, write_text
from benchlab.progress import for_terminal

if TYPE_CHECKING:
    import pandas as pd

    from benchlab.diagnose.engine import Diagnosis
    from benchlab.model.definition import ModelDefinition

NAME = "diagnose"
HELP = "find what the model gets wrong, name the cause, extend the model and measure the gain"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", help="run files")
    parser.add_argument("--baseline", "--model", dest="baseline", default="linear", metavar="MODEL",
                       help=f"the model to start from: {MODEL_HELP} (default linear, the paper's starting point)")
    parser.add_argument("--validate", metavar="V.h5", action="append", default=[],
                        help="repeatable: a run no fit sees; each finding's gain is measured on it as well (unseen "
                             "gain), and one whose gain does not carry to it is a lead, not a cause")
    parser.add_argument("--json", action="store_true", help="print the JSON object of docs/contract.md §3 on stdout")
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="seed of the baseline's starting points")
    parser.add_argument("--report", metavar="DIR", help="write the page into DIR: diagnose.md, the same page as diagnose.html for a browser, "
                        "and its PNG figures")
    parser.add_argument("--save-model", metavar="OUT.toml", type=cliargs.output_file,
                        help="write the best model found as a model file, its fitted values as starting values "
                             "(ready for identify --model OUT.toml)")
    parser.add_argument("--group-by", metavar="ATTR", type=cliargs.attribute_name,
                        help="a run attribute (bench, batch, specimen, ...) whose values group the runs when asking "
                             "whether the runs disagree on a parameter (default: every run on its own)")
    parser.add_argument("--force", action="store_true", help="replace an existing --save-model file and the files "
                                                             "of an existing --report directory (never a run file)")


def unseen_text(entry: dict) -> str:
    """A finding's or the best model's gain on the unseen runs, first on its line (empty without --validate)."""
    unseen = entry.get("unseen")
    if not unseen:
        return ""
    return (f"unseen runs {unseen['rmse_before_K']:.3f} -> {unseen['rmse_after_K']:.3f} K, gain "
            f"{unseen['gain_pct']:.1f} % (p = {unseen['p_value']:.2g}); ")


def alternative_lines(finding: dict) -> list[str]:
    """Each alternative of a finding or lead: what would tell it apart, then every place a sensor could go with what
    it is worth on the diagnosed runs (the design's wording, `design/sensors.py` `SensorWorth.line`)."""
    with interrupts_held():  # see benchlab.cli
        from benchlab.design.sensors import SensorWorth

    lines = []
    for a in finding.get("alternatives", []):
        lines.append(f"  not told apart from {a['candidate']} (held-out gain {a['gain_pct']:.1f} %, p = "
                     f"{a['p_vs_finding']:.2g} that the finding is better): {a['tell_apart_by']}")
        if a.get("sensors"):
            lines.append("    a sensor at each place, on these runs (what it removes of the plate's estimate "
                         "variance, what it adds to the test between the two):")
            lines += ["  " + SensorWorth(**place).line() for place in a["sensors"]]
    return lines


def print_report(result: dict) -> None:
    """The human-readable summary: baseline, worst held-out regime, strongest evidence, each finding (its gain on
    unseen runs first), the leads, the best model."""
    with interrupts_held():  # see benchlab.cli
        from benchlab.diagnose.regimes import worst_regimes

    base = result["baseline"]
    print(f"baseline {base['model']}: held-out RMSE {base['rmse_K']:.3f} K ({base['nrmse_pct']:.2f} %)")
    worst = worst_regimes(result["regimes"]["baseline"], 1)
    if worst:
        group, label, channel, rmse, samples = worst[0]
        print(f"  worst regime (held-out residuals): {group} = {label}, {channel} RMSE {rmse:.3f} K "
              f"over {samples} samples")
    top = result["evidence"][0]
    print(f"  strongest evidence: {top['signal']} explains {top['explained_pct']:.0f} % of the {top['channel']} "
          f"residual {top['form']} (circular shifts: {top['shifted_pct']:.0f} %, p = {top['p_value']:.3f})")
    for bound in result["method"]["baseline_bounds"]:
        print(f"  {bound['parameter']} = {bound['value']:.6g} sits on its {bound['bound']} ({bound['limit']:.6g}): "
              f"{bound['advice']}")
    if not result["findings"]:
        print("no finding: no extension lowers the held-out error significantly; the model is kept as it is")
    for f in result["findings"]:
        print(f"finding ({f['label']}): {f['summary']}\n  signal {f['signal']}, mechanism {f['mechanism']}, extension "
              f"{f['extension']}\n  {unseen_text(f)}held-out RMSE {f['rmse_before_K']:.3f} -> {f['rmse_after_K']:.3f} K, "
              f"gain {f['gain_pct']:.1f} % (p = {f['p_value']:.2g})"
              + (f", {f['run_gain_pct']:.1f} % on runs it was not fitted on" if f["run_gain_pct"] is not None else ""))
        for g in f.get("per_group", []):
            print(f"  {g['parameter']} for {g['group']} (runs {', '.join(map(str, g['runs']))}): {g['value']:.6g} "
                  f"± {g['standard_error']:.2g} {g['unit']}")
        if f["label"] != "cause":
            print(f"  a {f['label']}, not a cause: {'; '.join(f['label_reasons'])}")
        for line in alternative_lines(f):
            print(line)
    for lead in result["leads"]:
        print(f"lead ({lead['label']}, not a cause): {lead['candidate']} ({lead['signal']}/{lead['mechanism']}), "
              f"{unseen_text(lead)}held-out gain {lead['gain_pct']:.1f} %: {'; '.join(lead['label_reasons'])}")
        for line in alternative_lines(lead):
            print(line)
    best, floor = result["best"], result["floor"]
    print(f"best {best['model']}: {unseen_text(best)}held-out RMSE {best['rmse_K']:.3f} K ({best['nrmse_pct']:.2f} %)")
    print(f"noise floor of the measurements {floor['noise_K']:.4f} K: baseline {floor['baseline_ratio']:.1f}x, "
          f"best {floor['best_ratio']:.1f}x; {floor['verdict']}")


def load_diagnosed_runs(paths: list[str], model: ModelDefinition) -> list[pd.DataFrame]:
    """The run files, each holding what the model reads and long enough for the blocked cross-validation
    (two FOLD_S blocks)."""
    with interrupts_held():  # the reading's imports (see benchlab.cli)
        from benchlab.diagnose.engine import MIN_DURATION_S
        from benchlab.model.runs import load_runs

    runs = load_runs(paths, model)
    for path, run in zip(paths, runs):
        duration = float(run["time"].iloc[-1] - run["time"].iloc[0])
        if duration < MIN_DURATION_S:
            raise InputError(path, "/aligned/time", f"a run of at least {MIN_DURATION_S:.0f} s for held-out "
                                                    f"scoring, got {duration:.0f} s (a Table 1 run that long: "
                                                    f"benchlab run table1 --bench ... --duration {MIN_DURATION_S:.0f})")
    return runs


def best_values(diagnosis: Diagnosis) -> dict[str, float]:
    """The best model's fitted values, one per parameter (a parameter the runs disagree on: the median of its groups'
    values, as a model file and a parameter file have one value), without the runs' own start temperatures."""
    final = diagnosis.final
    split = {name: statistics.median([v for k, v in final.params.items() if k.split("@")[0] == name and "@" in k])
             for name in final.spec.per_group}
    return {k: v for k, v in {**final.params, **split}.items() if "@" not in k}


def best_model(diagnosis: Diagnosis) -> ModelDefinition:
    """The best model found, as a model file: the baseline's file with the accepted extensions, fitted values as starts
    (best_values)."""
    return diagnosis.final.spec.definition.with_starts(best_values(diagnosis), name=diagnosis.final.spec.name)


def run(args: argparse.Namespace) -> int:
    if args.save_model:
        check_output(args.save_model, "--save-model", args.force, inputs=args.runs + args.validate)
    out = check_output_dir(args.report, "--report", args.force) if args.report else None
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.diagnose.engine import diagnose_runs
        from benchlab.diagnose.report import summarise
        from benchlab.model.catalog import resolve_model
        from benchlab.model.definition import to_toml
    model = resolve_model(args.baseline, "--model")
    runs = load_diagnosed_runs(args.runs, model)
    unseen = load_diagnosed_runs(args.validate, model) if args.validate else []
    if args.group_by:
        with interrupts_held():
            from benchlab.runfile import load_attrs
        for path, frame in zip(args.runs, runs):
            attrs = load_attrs(path)
            if args.group_by not in attrs:
                raise InputError(path, args.group_by, f"a root attribute {args.group_by!r} (--group-by)")
            frame.attrs[args.group_by] = attrs[args.group_by]
    diagnosis = diagnose_runs(runs, model, seed=args.seed, progress=for_terminal(args.quiet), group_by=args.group_by,
                              validate=unseen)
    result = summarise(diagnosis, model.label)
    if args.save_model:
        write_text(args.save_model, to_toml(best_model(diagnosis)))
        result["best"]["model_file"] = str(args.save_model)
    if args.json:
        print(json.dumps(result, default=float))
    else:
        print_report(result)
    if out is not None:
        with interrupts_held():  # matplotlib only when a page is asked for
            from benchlab.diagnose.page import write_page

        page = write_page(diagnosis, result, runs, out)
        if not args.json:
            print(f"report: {page}")
    return 0
