"""`benchlab diagnose RUN.h5 [RUN2.h5 …] [--baseline linear|nonlinear] [--json]`."""

from __future__ import annotations

import argparse
import json

from benchlab.diagnose import diagnose
from benchlab.runfile import load_run

NAME = "diagnose"
HELP = "find what the model gets wrong, name the cause, extend the model and measure the gain"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", help="run files")
    parser.add_argument("--baseline", choices=("linear", "nonlinear"), default="linear")
    parser.add_argument("--json", action="store_true", help="print the contract's JSON object on stdout")
    parser.add_argument("--seed", type=int, default=0, help="seed of the baseline's starting points")


def print_report(result: dict) -> None:
    """The human-readable summary: baseline, each finding with its gain, the best model."""
    base = result["baseline"]
    print(f"baseline {base['model']}: held-out RMSE {base['rmse_K']:.3f} K ({base['nrmse_pct']:.2f} %)")
    worst = max(((k, v, e["rmse_K"]) for k, group in result["regimes"]["baseline"].items()
                 for v, e in group.items()), key=lambda item: item[2])
    print(f"  worst regime: {worst[0]} = {worst[1]}, flywheel RMSE {worst[2]:.3f} K")
    if not result["findings"]:
        print("no finding: no extension lowers the held-out error significantly; the model is kept as it is")
    for f in result["findings"]:
        print(f"finding: {f['summary']}\n  signal {f['signal']}, mechanism {f['mechanism']}, extension "
              f"{f['extension']}\n  held-out RMSE {f['rmse_before_K']:.3f} -> {f['rmse_after_K']:.3f} K, "
              f"gain {f['gain_pct']:.1f} % (p = {f['p_value']:.2g})")
    best = result["best"]
    print(f"best {best['model']}: held-out RMSE {best['rmse_K']:.3f} K ({best['nrmse_pct']:.2f} %)")


def run(args: argparse.Namespace) -> int:
    result = diagnose([load_run(p) for p in args.runs], args.baseline, seed=args.seed)
    if args.json:
        print(json.dumps(result, default=float))
    else:
        print_report(result)
    return 0
