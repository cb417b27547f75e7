"""`benchlab wear RUN.h5 --params P.json [--model FILE.toml|linear|nonlinear] [--clutch CLUTCH.toml] [--predict N]
[--json] [--plot OUT.png]`."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.bounds import MAX_WEAR_HORIZON, MAX_WEAR_PATHS
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.model.options import add_model_option, load_model_params
from benchlab.outputs import check_output
from benchlab.values import json_ready
from benchlab.wear.defaults import DEFAULT_HORIZON, DEFAULT_PATHS

if TYPE_CHECKING:
    from benchlab.wear.analysis import WearReport

NAME = "wear"
HELP = "friction energy, lining wear, health and remaining life from a run (eq. 1-3)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments (contract section 3 plus the Monte Carlo's size and seed)."""
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--params", required=True, help="thermal parameter file (JSON)")
    add_model_option(parser)
    parser.add_argument("--clutch", help="clutch file (TOML: z, r, maps of eq. 1-3); default: documented assumptions")
    parser.add_argument("--predict", type=cliargs.count("engagements", MAX_WEAR_HORIZON), default=DEFAULT_HORIZON,
                        metavar="N_ENGAGEMENTS",
                        help=f"horizon for the failure probability and expected wear (default {DEFAULT_HORIZON})")
    parser.add_argument("--paths", type=cliargs.count("Monte Carlo paths", MAX_WEAR_PATHS), default=DEFAULT_PATHS,
                        help="Monte Carlo paths for the remaining life")
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="Monte Carlo seed")
    parser.add_argument("--json", action="store_true", help="print the result as one JSON object")
    parser.add_argument("--plot", metavar="OUT.png", type=cliargs.output_file,
                        help="write a figure of energy, temperature, wear and life")
    parser.add_argument("--force", action="store_true", help="replace an existing --plot file (never a run file)")


def _percentiles(values: dict[str, float | None]) -> str:
    return " / ".join("n/a" if values[k] is None else f"{values[k]:.0f}" for k in ("p10", "p50", "p90"))


def _summary(report: WearReport) -> str:
    """A few human-readable lines: energy, per-side wear, health, remaining life, μ estimate."""
    doc = report.as_dict()
    life, health = doc["life"], doc["health"]
    lines = [f"friction energy {doc['friction_energy_J'] / 1e3:.1f} kJ in {doc['engagements']} engagements "
             f"({doc['slip_time_s']:.1f} s slipping), split plate/flywheel {report.split:.2f}"]
    for side, s in doc["wear"].items():
        mean_c = s["mean_lining_temperature_C"]
        lines.append(f"{side:>8} side: {s['energy_J'] / 1e3:.1f} kJ at mean "
                     f"{'n/a' if mean_c is None else format(mean_c, '.1f')} degC, "
                     f"wear {s['wear_run_mm'] * 1e3:.3f} um, height {s['height_mm']:.4f} mm, mu {s['mu_at_rating']:.4f}")
    lines.append(f"health {health['health']:.4f} ({'WORN' if health['worn'] else 'ok'}, "
                 f"limited by {health['limited_by']}): {health['transmissible_torque_Nm']:.1f} N*m transmissible "
                 f"vs {health['max_engine_torque_Nm']:.1f} N*m engine")
    lines.append(f"remaining life P10/P50/P90: {_percentiles(life['engagements'])} engagements, "
                 f"{_percentiles(life['hours'])} h; "
                 f"P(worn within {life['horizon_engagements']}) = {life['p_fail_within_horizon']:.3f}")
    if doc["mu_estimate"]:
        mu = doc["mu_estimate"]
        lines.append(f"mu estimated from actuator position: median {mu['median']:.3f} (model {mu['model_median']:.3f}, "
                     f"{mu['samples']} samples)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Analyse the run; print JSON or a summary, optionally write the figure."""
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.model.runs import load_runs
        from benchlab.runfile import REQUIRED
        from benchlab.wear.analysis import analyse_wear
        from benchlab.wear.clutchfile import default_clutch, load_clutch
    if args.plot:
        check_output(args.plot, "--plot", args.force,
                     inputs=[args.run, args.params, *([args.clutch] if args.clutch else [])])
    spec = load_clutch(args.clutch) if args.clutch else default_clutch()
    params = load_model_params(args.params, args.model)
    measured = load_runs([args.run], params.definition, params, args.params)[0]
    for channel in REQUIRED:  # friction energy and slip need the clutch's channels, whatever the thermal model
        if channel not in measured.columns:
            raise InputError(args.run, f"/aligned/{channel}", "a clutch channel wear needs (missing)")
    report = analyse_wear(measured, params, spec, horizon=args.predict, paths=args.paths, seed=args.seed,
                          params_source=str(args.params))
    if args.plot:
        with interrupts_held():  # matplotlib only when a figure is asked for
            from benchlab.wear.plot import plot_wear

        plot_wear(report, args.plot)
    if args.json:
        print(json.dumps(json_ready(report.as_dict()), default=float))
    else:
        print(_summary(report))
    return 0
