"""`benchlab import DATA.csv --out RUN.h5`: a CSV with the /aligned column names becomes a run file."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab import cliargs
from benchlab.errors import InputError
from benchlab.runfile import ALIGNED_UNITS, REQUIRED, time_step_tolerance, unmeasurable_sample, write_run

NAME = "import"
HELP = "convert a CSV with the /aligned column names (contract units) into a run file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("csv", help="CSV file, one column per channel, header = channel names")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="run file to write")


def read_csv(path: Path) -> tuple[pd.DataFrame, float]:
    """Read and check the CSV: required columns, numeric values, uniform time; return frame and dt."""
    if not path.exists():
        raise InputError(path, "file", "an existing CSV file (not found)")
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(path, "file", f"a CSV table ({str(exc).splitlines()[0]})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    for name in REQUIRED:
        if name not in frame.columns:
            raise InputError(path, f"column {name}", f"a required channel in {ALIGNED_UNITS[name]} (missing)")
    unknown = [c for c in frame.columns if c not in ALIGNED_UNITS]
    if unknown:
        raise InputError(path, f"column {unknown[0]}", f"one of the contract's channels {sorted(ALIGNED_UNITS)}")
    for name in frame.columns:
        values = pd.to_numeric(frame[name], errors="coerce")
        bad = values.isna() & frame[name].notna() & (frame[name].astype(str).str.strip() != "")
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0]) + 2
            raise InputError(path, f"column {name}, line {row}", f"a number, got {frame[name].iloc[row - 2]!r}")
        frame[name] = values.astype(np.float64)
        if name != "time" and (problem := unmeasurable_sample(name, ALIGNED_UNITS[name], frame[name].to_numpy())):
            raise InputError(path, f"column {name}, line {problem[0] + 2}", f"{problem[1]}, got {problem[2]!r}")
    time = frame["time"].to_numpy()
    if len(time) < 2 or not np.all(np.isfinite(time)):
        raise InputError(path, "column time", "at least two finite time stamps")
    dt = float(np.median(np.diff(time)))
    if dt <= 0 or np.max(np.abs(np.diff(time) - dt)) > time_step_tolerance(time, dt, np.dtype(np.float64)):
        raise InputError(path, "column time", "a uniform time grid in s (resample before importing)")
    return frame, dt


def run(args: argparse.Namespace) -> int:
    frame, dt = read_csv(Path(args.csv))
    write_run(args.out, frame, dt, protocol="imported")
    print(f"{args.out}: {len(frame)} samples at dt={dt:g} s, {len(frame.columns)} channels")
    return 0
