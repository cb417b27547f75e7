"""`benchlab run PROTOCOL --bench sim|BENCH.toml --out RUN.h5`: run a protocol, acquire, write a run file.

The bench is always named: without --bench nothing runs (a simulated run must never pass for a measured one), and
the summary, the run file's `bench` attribute and every page made from it say which bench it was."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from benchlab import cliargs
from benchlab.bounds import MAX_CYCLES, MAX_REALTIME_FACTOR, MAX_RUN_DURATION_S, MIN_REALTIME_FACTOR
from benchlab.commands import watch
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.outputs import check_output
from benchlab.progress import for_terminal
from benchlab.provenance import SIMULATED
from protocols.catalog import NAMES
from sim_bench.faults import SPEC, kinds_help

NAME = "run"
HELP = "run a protocol (table1, cooldown-sweep, validation) on the simulated bench or a hardware bench"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("protocol", nargs="?", help=f"protocol: {', '.join(NAMES)}, or a PLAN.json of `benchlab design` "
                        "(taken from the file with --resume)")
    parser.add_argument("--bench", help="required: 'sim' for the simulated bench (emulated devices, a model plant) "
                                         "or a hardware bench's BENCH.toml")
    parser.add_argument("--seed", type=cliargs.seed, default=1, help="seed of the schedule and the simulated bench")
    parser.add_argument("--cycles", type=cliargs.count("a number of cycles", MAX_CYCLES),
                        help="number of cycles (cooldown-sweep: grid points)")
    parser.add_argument("--duration", type=cliargs.positive_float("a duration in s", MAX_RUN_DURATION_S),
                        help="table1: cycles are drawn until the plan lasts at least this many s (launches at "
                             "their time to synchronise, so the run is at least this long)")
    parser.add_argument("--grid", help="cooldown-sweep grid: RPM:S[:SLIP_RPM],... e.g. 1000:1,1000:0,2000:0:500")
    parser.add_argument("--out", type=cliargs.output_file, help="run file to write (HDF5)")
    parser.add_argument("--dry-run", action="store_true", help="print the schedule, check limits, estimate duration")
    parser.add_argument("--resume", metavar="RUN.h5", help="continue an interrupted run with its next planned cycle")
    parser.add_argument("--params", help="cooldown-sweep: analyse the cool-downs with this parameter file "
                        "(or 'sim-truth') after the run and store /analysis (see `benchlab cooldown`); on a hardware "
                        "bench its model also times the heat-ups and cool-downs in the plan (--dry-run's estimate)")
    parser.add_argument("--plant", choices=("reference", "paper"),
                        help="--bench sim: the simulated clutch, the reference plant (default, docs/plant.md) or the "
                             "paper's network; a resumed run keeps its own")
    parser.add_argument("--fault", type=cliargs.fault, action="append", default=[], metavar=SPEC,
                        help="simulated bench only, repeatable: inject a fault at SECONDS of run time to rehearse "
                        f"what the bench does (recorded in the run file's sim_faults); kinds(keys): {kinds_help()}")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file (a regular file)")
    parser.add_argument("--watch", action="store_true", help="serve the live view of the run on 127.0.0.1 while it "
                        "runs (as `benchlab watch`, in a process of its own)")
    parser.add_argument("--port", type=watch.port, help=f"with --watch: its port (default {watch.DEFAULT_PORT})")
    parser.add_argument("--realtime", nargs="?", const=1.0, type=realtime_factor, metavar="FACTOR",
                        help="simulated bench only: run at FACTOR x real time (1 if FACTOR is left out; with --watch "
                             "1 unless given) to rehearse the live view, Ctrl-C and the interlocks at a bench's pace")


def realtime_factor(text: str) -> float:
    """--realtime's FACTOR: a speed-up over real time, with a hint when a protocol name landed here instead."""
    try:
        return cliargs.ranged_float("a speed-up over real time", MIN_REALTIME_FACTOR, MAX_REALTIME_FACTOR)(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (give PROTOCOL before --realtime)") from None


def run(args: argparse.Namespace) -> int:
    """The run file is locked before anything else (RunFileLock), so a second run on it is refused."""
    if args.bench is None:
        raise InputError("command line", "--bench", "'sim' to run on the simulated bench, or a hardware bench's "
                                                    "BENCH.toml (nothing runs without naming the bench)")
    if args.realtime is not None and args.bench != SIMULATED:
        raise InputError("command line", "--realtime", f"--bench sim: a hardware bench runs at real time "
                                                       f"(got --bench {args.bench})")
    if args.fault and args.bench != "sim":
        raise InputError("command line", "--fault", "--bench sim: faults are rehearsed on the simulated bench, "
                                                    f"never injected into a hardware bench (got --bench {args.bench})")
    if args.fault and args.resume:
        raise InputError("command line", "--fault", "a new run: a resumed run continues as it was planned")
    if args.resume:
        out = Path(args.resume)
        if args.out and Path(args.out) != out:
            raise InputError("--out", "--out", "the same file as --resume (a run is resumed in place)")
    elif not args.dry_run and not args.out:
        raise InputError("command line", "--out", "a run file to write")
    else:
        out = Path(args.out or "dry-run.h5")
    if args.port is not None and not args.watch:
        raise InputError("command line", "--port", "--watch with it (the live view's port)")
    if args.dry_run:
        return _run(args, out)
    if not args.resume:  # the output rule (benchlab.outputs) before the lock file is made beside it
        check_output(out, "--out", args.force, run_file=True, hint="--resume to continue it")
    with interrupts_held():  # the lock's package loads h5py (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.acquire.lock import RunFileLock
    with RunFileLock(out, "--resume" if args.resume else "--out"):  # before anything else: one run per file
        if not args.watch:
            return _run(args, out)
        with interrupts_held():
            from benchlab.watch.launch import watching

        with watching(out, watch.DEFAULT_PORT if args.port is None else args.port) as url:
            print(f"live view  {url}", file=sys.stderr, flush=True)
            return _run(args, out)


def design_plan(protocol: str | None) -> "tuple[tuple, dict] | None":
    """A plan file of `benchlab design` (its schedule and what the run file records of it), or None where PROTOCOL
    names no .json file; InputError naming the plan's field that is not as docs/contract.md §3 says."""
    if protocol is None or not protocol.endswith(".json") or not Path(protocol).is_file():
        return None
    from benchlab.commands.design import PLAN_SCHEMA
    from benchlab.errors import read_document
    from protocols.schedule import steps_from_rows

    doc = read_document(protocol, "plan file", json.loads, (ValueError,), "a JSON object")
    if not isinstance(doc, dict) or doc.get("schema") != PLAN_SCHEMA:
        raise InputError(protocol, "schema", f"{PLAN_SCHEMA!r} (a plan of `benchlab design`)")
    steps = steps_from_rows(doc.get("schedule"), protocol)
    return steps, {"plan": str(protocol), "kind": doc.get("kind"), "blocks": doc.get("blocks"),
                   "expected": doc.get("expected")}


def _plant(args: argparse.Namespace, out: Path) -> str:
    """The simulated bench's plant: --plant, else the reference; a resumed run's own (its `sim_truth`; the paper's
    in files written before the reference plant), and --plant must agree with it."""
    if not args.resume or args.bench != "sim" or not out.is_file():
        return args.plant or "reference"
    from benchlab.runfile import load_attrs

    truth = load_attrs(out).get("sim_truth")
    recorded = json.loads(truth).get("plant", "paper") if truth is not None else "reference"
    if args.plant is not None and args.plant != recorded:
        raise InputError(out, "sim_truth", f"--plant {recorded} (the run was made on the {recorded} plant), "
                                           f"got --plant {args.plant}")
    return recorded


def _run(args: argparse.Namespace, out: Path) -> int:
    """Check the rest of the command line, run (or dry-run) the protocol, print the summary."""
    plan = design_plan(args.protocol) if not args.resume and args.protocol not in NAMES else None
    if not args.resume and args.protocol not in NAMES and plan is None:
        raise InputError("command line", "PROTOCOL", f"one of {', '.join(NAMES)} or a PLAN.json, got {args.protocol!r}")
    if args.bench != "sim" and not Path(args.bench).is_file():
        found = "a directory" if Path(args.bench).is_dir() else "not found"
        raise InputError(args.bench, "--bench", f"'sim' or an existing BENCH.toml ({found})")
    if args.params is not None and args.params != "sim-truth":  # read and checked before the protocol runs (hours
        from benchlab.commands.cooldown import load_analysis_params  # on hardware), not after it

        load_analysis_params(args.params, out)
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.runner.session import RunRequest, execute
    bench = args.bench
    realtime = args.realtime if args.realtime is not None or not args.watch else 1.0
    if args.plant is not None and args.bench != SIMULATED:
        raise InputError("command line", "--plant", "--bench sim (a hardware bench has its own clutch)")
    plant = _plant(args, out)
    if args.bench == SIMULATED and (plant != "reference" or (args.fault or realtime is not None) and not args.dry_run):
        with interrupts_held():  # the simulated bench: its plant, the faults to rehearse, the pace asked for
            from sim_bench.bench import SimulatedBench
            from sim_bench.reference_plant import plant_named

        bench = SimulatedBench(plant_named(plant), faults=tuple(args.fault), realtime=realtime)
    request = RunRequest(protocol="design" if plan else args.protocol or "", out=out, bench=bench, seed=args.seed, cycles=args.cycles,
                         duration_s=args.duration, grid=args.grid, dry_run=args.dry_run, resume=bool(args.resume),
                         progress=for_terminal(args.quiet), steps=plan[0] if plan else None,
                         options=plan[1] if plan else None, params=args.params)
    code, summary = execute(request)
    if summary is not None:
        print("\n".join(summary.lines()))
        print(f"run file   {out}")
        if args.params and code == 0 and (args.protocol == "cooldown-sweep" or args.resume):
            from benchlab.commands import cooldown

            cooldown.run(argparse.Namespace(run=str(out), params=args.params, sample=1.0, json=False, out=None,
                                            store=True, force=False, no_store=False, quiet=args.quiet))
    return code
