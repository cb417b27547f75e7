"""`benchlab export RUN.h5 --to OUT.mf4|OUT.csv|OUT.parquet [--channels NAME,…] [--start S] [--stop S]
[--raster S] [--force]`."""

from __future__ import annotations

import argparse

from benchlab import cliargs
from benchlab.bounds import MAX_RUN_DURATION_S
from benchlab.interrupts import interrupts_held

NAME = "export"
HELP = "write a run file as MDF4 (.mf4: every stream at its own rate, for asammdf/CANape), CSV or Parquet (/aligned)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--to", required=True, type=cliargs.output_file, metavar="OUT",
                        help="file to write: .mf4 (MDF 4.10), .csv or .parquet (needs the [export] extra)")
    parser.add_argument("--channels", action="extend", type=_names, metavar="NAME[,NAME…]",
                        help="only these channels (their export names: T_air, can_drive.speed, events.kind, ...), "
                             "separated by commas or the option repeated")
    run_time = cliargs.signed_float("a run time in s", MAX_RUN_DURATION_S)
    parser.add_argument("--start", type=run_time, metavar="S", help="from this run time on (s)")
    parser.add_argument("--stop", type=run_time, metavar="S", help="up to this run time (s)")
    parser.add_argument("--raster", type=cliargs.positive_float("a raster in s", MAX_RUN_DURATION_S), metavar="S",
                        help="every channel group on one raster of S seconds (states and counters held, the rest "
                             "interpolated; a gap stays empty)")
    parser.add_argument("--force", action="store_true", help="replace an existing OUT (a regular file, never a run "
                                                             "file)")


def _names(text: str) -> list[str]:
    """`T_air,T_flywheel` -> the channel names."""
    return [name.strip() for name in text.split(",") if name.strip()]


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # asammdf and pyarrow load only when exporting (Ctrl-C meanwhile: see benchlab.cli)
        from benchlab.export import export

    content = export(args.run, args.to, args.force, args.channels or None, args.start, args.stop, args.raster)
    groups = content.groups if args.to.lower().endswith(".mf4") else content.groups[:1]
    skipped = f", {content.skipped_rows} rows without a time stamp skipped" if content.skipped_rows else ""
    print(f"{args.to}: {len(groups)} channel group(s), {sum(len(g.channels) + 1 for g in groups)} channels "
          f"(time included), {len(content.aligned.time)} samples on /aligned{skipped}")
    return 0
