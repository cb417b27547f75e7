"""`benchlab observe RUN.h5 --params P.json [--model FILE.toml|linear|nonlinear] [--sensors T_air,…] [--initial-offset K]
--out EST.h5 [--plot FIG.png]` (and --reinit, --adapt, noise overrides: docs/observer.md)."""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.model.options import add_model_option, load_model_params
from benchlab.outputs import check_output

if TYPE_CHECKING:
    from benchlab.observer.model import Reset

NAME = "observe"
HELP = "Kalman observer: every temperature (the pressure plate too) with its spread, from the sensors chosen"
#: Largest start offset, noise figure and re-initialisation time the command takes (typos, not clutches).
MAX_OFFSET_K = 500.0
MAX_HEAT_FLOW_W = 1e6
MAX_SENSOR_K = 100.0
MAX_TIME_S = 7 * 24 * 3600.0
#: Truth scores skip the first seconds: a start made wrong on purpose needs them to converge.
SETTLE_S = 300.0


def _sensors(text: str) -> list[str]:
    """`T_air,T_flywheel` -> channel names; `none` (or empty) -> no sensor: the model alone, open loop."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    return [] if names == ["none"] else names


def _reset(text: str) -> Reset:
    """`CHANNEL@SECONDS` -> a re-initialisation of the state CHANNEL reads, from its reading at that time."""
    with interrupts_held():  # the observer's imports, at parse time (see benchlab.cli)
        from benchlab.observer.model import Reset

    channel, at, seconds = text.partition("@")
    try:
        value = float(seconds)
    except ValueError:
        value = math.nan
    if not at or not channel.strip() or not (math.isfinite(value) and 0 <= value <= MAX_TIME_S):
        raise argparse.ArgumentTypeError(f"CHANNEL@SECONDS with 0 <= SECONDS <= {MAX_TIME_S:g}, e.g. "
                                         f"T_housing@0, got {text!r}")
    return Reset(channel.strip(), value)



def _sensor_noise(text: str) -> tuple[str, float]:
    channel, _, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not channel.strip() or not (math.isfinite(number) and 0 < number <= MAX_SENSOR_K):
        raise argparse.ArgumentTypeError(f"CHANNEL=K with a positive noise up to {MAX_SENSOR_K:g} K, got {text!r}")
    return channel.strip(), number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--params", required=True, help="parameter file (JSON); its residual statistics tune the noise")
    add_model_option(parser)
    parser.add_argument("--sensors", type=_sensors, default=["T_air"],
                        help="measured channels the observer uses, comma-separated (default T_air, the paper's extra "
                             "sensor; 'none' for the model alone)")
    parser.add_argument("--reinit", type=_reset, action="append", default=[], metavar="CHANNEL@SECONDS",
                        help="re-initialise the state CHANNEL reads from its reading at that time, without using it as "
                             "an observer input (e.g. an oil temperature at engine start); repeatable")
    parser.add_argument("--adapt", action="append", default=[], metavar="LINK",
                        help="correct the resistance law of this link online (e.g. R_PA: eq. 11, shared with R_FA); "
                             "an extended Kalman filter; repeatable")
    parser.add_argument("--initial-offset", type=cliargs.signed_float("a temperature offset in K", MAX_OFFSET_K), default=0.0, metavar="K",
                        help="start every estimate K away from where simulate starts it (the start is then known to "
                             "within |K| at best)")
    parser.add_argument("--initial-std", type=cliargs.positive_float("an initial spread in K", MAX_OFFSET_K),
                        metavar="K", help="spread of every state at the start (default: 2 K, or |--initial-offset|)")
    parser.add_argument("--process-noise", type=cliargs.positive_float("a heat-flow noise in W*sqrt(s)",
                                                                       MAX_HEAT_FLOW_W),
                        metavar="W", help="heat-flow noise density on every node (default: from the residuals)")
    parser.add_argument("--sensor-noise", type=_sensor_noise, action="append", default=[], metavar="CHANNEL=K",
                        help="reading noise of a sensor (default: its residual RMS); repeatable")
    parser.add_argument("--no-model-spread", action="store_true",
                        help="the filter's band alone for the states no sensor reads (default: widened by the spread "
                             "of their prediction across the parameter sets the identification holds plausible)")
    parser.add_argument("--clutch", help="clutch file (TOML) for the online wear; default: documented assumptions")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="file to write: the run's root attributes and /aligned plus "
                                                                          "/estimated (a run file)")
    parser.add_argument("--plot", type=cliargs.output_file, help="figure (PNG): estimates, ±2σ band, measurement, "
                                                                  "truth where the run has it")
    parser.add_argument("--force", action="store_true", help="replace existing --out and --plot files (never a run "
                                                             "file)")


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        import numpy as np

        from benchlab.model.runs import load_runs
        from benchlab.observer.batch import STD_SUFFIX, WEAR_UNITS, estimated_wear, observe
        from benchlab.observer.consistency import WINDOW_S
        from benchlab.observer.noise import tune_noise, with_overrides
        from benchlab.observer.spread import DRAWS, FILTER_STD_SUFFIX, model_spread, widened
        from benchlab.runfile import load_truth, write_beside_run
        from benchlab.wear.clutchfile import default_clutch, load_clutch
    inputs = [args.run, args.params, *([args.clutch] if args.clutch else [])]
    check_output(args.out, "--out", args.force, inputs=inputs, run_file=True)
    if args.plot:
        check_output(args.plot, "--plot", args.force, inputs=[*inputs, args.out])
    params = load_model_params(args.params, args.model)
    measured = load_runs([args.run], params.definition, params, args.params)[0]
    clutch = load_clutch(args.clutch) if args.clutch else default_clutch()
    network = params.network
    channels = [*args.sensors, *(r.channel for r in args.reinit)]
    for channel, _ in args.sensor_noise:
        if channel not in channels:
            raise InputError("--sensor-noise", channel, f"one of the sensors or re-initialising channels "
                                                        f"({', '.join(channels) or 'none given'})")
    noise = with_overrides(tune_noise(network, params, channels, args.initial_offset), args.process_noise,
                           dict(args.sensor_noise), args.initial_std)
    result = observe(measured, params, args.sensors, network, args.reinit, args.initial_offset, noise, args.adapt)
    unmeasured = [result.model.names[s] for s in result.model.states
                  if result.model.names[s] not in result.model.sensors]
    spread = None if args.no_model_spread else model_spread(measured, params, unmeasured)
    if spread is not None:
        result = widened(result, spread)
    truth = load_truth(args.run)
    units = {name: ("K/W" if name in result.model.adapted else "degC") for name in result.estimate.columns
             if not name.endswith(STD_SUFFIX)}
    columns = {}
    for name, unit in units.items():
        columns[name] = (result.estimate[name].to_numpy(), unit, f"observer estimate of {name}")
        columns[name + STD_SUFFIX] = (result.estimate[name + STD_SUFFIX].to_numpy(), "K/W" if unit == "K/W" else "K",
                                      f"standard deviation of the estimate of {name}")
        if name + FILTER_STD_SUFFIX in result.estimate:
            columns[name + FILTER_STD_SUFFIX] = (result.estimate[name + FILTER_STD_SUFFIX].to_numpy(), "K",
                                                 f"standard deviation of the estimate of {name} given the parameter "
                                                 f"file (the filter's alone, without the model-form spread)")
    wear = estimated_wear(measured, result, params, clutch)
    for name, values in (wear or {}).items():
        columns[name] = (values, WEAR_UNITS[name], "wear at the estimated temperatures, cumulative")
    seen = result.observability
    write_beside_run(args.out, args.run, "estimated", measured["time"].to_numpy(), columns, {
        "source_run": str(args.run), "params": str(args.params), "model": params.model,
        "sensors": json.dumps(list(result.model.sensors)),
        "reinit": json.dumps([[r.channel, r.time_s] for r in args.reinit]), "adapt": json.dumps(result.model.adapted),
        "initial_offset_K": float(args.initial_offset), "noise": json.dumps(noise.as_dict()),
        "observability": json.dumps(seen.as_dict()),
        "consistency": json.dumps([c.as_dict() for c in result.consistency]),
        "model_spread": json.dumps({"states": [] if spread is None else list(spread.columns),
                                    "draws": 0 if spread is None or not spread.to_numpy().any() else DRAWS})})
    print(f"{args.out}: {len(measured)} samples, {params.model} model, sensors "
          f"{', '.join(result.model.sensors) or 'none (open loop)'}, noise from {noise.origin}")
    observable = [s for s in seen.states if seen.observable[s]]
    print(f"observability: rank {seen.rank} of {len(seen.states)} from {', '.join(seen.sensors) or 'no sensor'}; "
          f"observable: {', '.join(observable) or 'none'}")
    for line in seen.warnings():
        print(f"warning: {line}")
    for c in result.consistency:
        verdict = "consistent" if c.consistent else "NOT consistent"
        print(f"innovations {c.sensor}: mean NIS {c.mean_nis:.2f} (1 when the spread is right), {c.outside_pct:.0f} % "
              f"of {c.windows} windows of {WINDOW_S:.0f} s outside the 99 % chi-square bound: {verdict}")
    wrong = [c.sensor for c in result.consistency if not c.consistent]
    if wrong:
        print(f"warning: the ±2σ band is not to be trusted: the innovations of {', '.join(wrong)} exceed the "
              f"filter's stated spread (the model or its noise is wrong; unmeasured states' bands are too narrow)")
    if spread is not None and spread.to_numpy().any():
        widths = ", ".join(f"{name} mean 2σ {np.mean(2 * result.estimate[name + STD_SUFFIX]):.3g} K (filter alone "
                           f"{np.mean(2 * result.estimate[name + FILTER_STD_SUFFIX]):.3g} K)" for name in spread.columns)
        print(f"model-form spread of the states no sensor reads, over {DRAWS} parameter sets the identification "
              f"holds plausible (docs/observer.md): {widths}")
    elif spread is not None:
        print("the parameter file states no uncertainty: the bands are the filter's alone, given its parameters")
    time = measured["time"].to_numpy()
    for name, unit in units.items():
        value, spread = result.estimate[name].to_numpy(), result.estimate[name + STD_SUFFIX].to_numpy()
        text = f"  {name:18s} at the end {value[-1]:9.4g} ± {2 * spread[-1]:.3g} {unit} (2σ)"
        if truth is not None and name in truth.columns:
            late = time >= min(SETTLE_S, time[-1] / 2)
            error = value - truth[name].to_numpy()
            text += (f"; against /truth after {time[late][0]:.0f} s: RMS {np.sqrt(np.mean(error[late] ** 2)):.3f} K, "
                     f"±2σ band covers {100 * np.mean(np.abs(error[late]) <= 2 * spread[late]):.1f} %")
        print(text)
    if wear:
        print(f"  wear at the estimated temperatures: plate {wear['wear_plate_mm'][-1]:.3g} mm, flywheel "
              f"{wear['wear_flywheel_mm'][-1]:.3g} mm per face")
    if args.plot:
        with interrupts_held():  # matplotlib only when a figure is asked for
            from benchlab.observer.plot import plot_observation

        print(f"figure: {plot_observation(measured, result, truth, args.plot)}")
    return 0
