"""`benchlab export RUN.h5 --to OUT.mf4|OUT.csv|OUT.parquet [--force]`."""

from __future__ import annotations

import argparse

from benchlab import cliargs
from benchlab.interrupts import interrupts_held

NAME = "export"
HELP = "write a run file as MDF4 (.mf4: every stream at its own rate, for asammdf/CANape), CSV or Parquet (/aligned)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="run file (HDF5, benchlab-run/1)")
    parser.add_argument("--to", required=True, type=cliargs.output_file, metavar="OUT",
                        help="file to write: .mf4 (MDF 4.10), .csv or .parquet (needs the [export] extra)")
    parser.add_argument("--force", action="store_true", help="replace an existing OUT (a regular file, never a run "
                                                             "file)")


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # asammdf and pyarrow load only when exporting (Ctrl-C meanwhile: see benchlab.cli)
        from benchlab.export import export

    content = export(args.run, args.to, args.force)
    groups = content.groups if args.to.lower().endswith(".mf4") else content.groups[:1]
    skipped = f", {content.skipped_rows} rows without a time stamp skipped" if content.skipped_rows else ""
    print(f"{args.to}: {len(groups)} channel group(s), {sum(len(g.channels) + 1 for g in groups)} channels "
          f"(time included), {len(content.aligned.time)} samples on /aligned{skipped}")
    return 0
