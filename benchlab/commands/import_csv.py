"""`benchlab import DATA.csv --out RUN.h5 [--dt S] [--unit NAME=UNIT …] [--model FILE.toml|linear|nonlinear]`:
a CSV becomes a run file (contract sections 1 and 6).

Columns with the contract's /aligned names carry the contract's units; any other column needs its unit, from a
second header line of units or `--unit NAME=UNIT`. Without a `time` column, `--dt S` gives the grid. The CSV
must hold the clutch channels of section 1, or with `--model` the channels that model names.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab import cliargs
from benchlab.bounds import MAX_RUN_DURATION_S
from benchlab.errors import InputError
from benchlab.model.catalog import MODEL_HELP, resolve_model
from benchlab.runfile import ALIGNED_UNITS, REQUIRED, time_step_tolerance, unmeasurable_sample, write_run

NAME = "import"
HELP = "convert a CSV (contract channel names, or any channel with its unit) into a run file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("csv", help="CSV file, one column per channel, header = channel names "
                                    "(optionally a second header line of units)")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="run file to write")
    parser.add_argument("--dt", type=cliargs.positive_float("a time step in s", MAX_RUN_DURATION_S),
                        help="time step in s of a CSV without a time column (one row per step)")
    parser.add_argument("--unit", action="extend", nargs="+", default=[], metavar="NAME=UNIT",
                        help="the unit of each column beyond the contract's channels, e.g. --unit IqFbk=A speed=rpm")
    parser.add_argument("--model", help=f"{MODEL_HELP}: the CSV must hold the channels it names "
                                        "(default: the clutch channels of contract section 1)")


def parse_units(items: list[str]) -> dict[str, str]:
    """`NAME=UNIT` options as a dict; bad input names the item."""
    units = {}
    for item in items:
        name, sep, unit = (part.strip() for part in item.partition("="))
        if not sep or not name or not unit:
            raise InputError("--unit", item, "NAME=UNIT, e.g. IqFbk=A")
        units[name] = unit
    return units


def _is_number(text: object) -> bool:
    try:
        float(str(text))
    except ValueError:
        return False
    return True


def read_csv(path: Path, dt: float | None = None, units: dict[str, str] | None = None,
             required: tuple[str, ...] = REQUIRED) -> tuple[pd.DataFrame, float, dict[str, str]]:
    """Read and check the CSV: required columns, a unit for every column, numeric values, a uniform time grid
    (or `dt`); return frame, dt and the units."""
    if not path.exists():
        raise InputError(path, "file", "an existing CSV file (not found)")
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(path, "file", f"a CSV table ({str(exc).splitlines()[0]})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    first_line = 2
    if len(frame) and not any(_is_number(v) for v in frame.iloc[0]):  # a second header line: the units
        header_units = {c: str(u).strip() for c, u in zip(frame.columns, frame.iloc[0]) if str(u).strip()}
        frame = frame.iloc[1:].reset_index(drop=True)
        first_line = 3
    else:
        header_units = {}
    units = _units(path, list(frame.columns), {**header_units, **dict(units or {})})
    if dt is not None and "time" in frame.columns:
        raise InputError(path, "column time", "no time column with --dt (one or the other gives the grid)")
    if dt is None and "time" not in frame.columns:
        raise InputError(path, "column time", "a time column in s, or --dt S for one row per step")
    for name in ("time",) + tuple(required):
        if name not in frame.columns and not (name == "time" and dt is not None):
            raise InputError(path, f"column {name}", f"a required channel in {ALIGNED_UNITS.get(name, 'its unit')} "
                                                     "(missing)")
    for name in frame.columns:
        text = frame[name].astype(str).str.strip()
        values = pd.to_numeric(text.replace({"": np.nan, "nan": np.nan, "NaN": np.nan}), errors="coerce")
        bad = values.isna() & ~text.isin(["", "nan", "NaN"])
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(path, f"column {name}, line {row + first_line}", f"a number, got {frame[name].iloc[row]!r}")
        frame[name] = values.astype(np.float64)
        if name != "time" and (problem := unmeasurable_sample(name, units[name], frame[name].to_numpy())):
            raise InputError(path, f"column {name}, line {problem[0] + first_line}", f"{problem[1]}, got {problem[2]!r}")
    if dt is not None:
        frame.insert(0, "time", np.arange(len(frame)) * dt)
        units["time"] = "s"
    time = frame["time"].to_numpy()
    if len(time) < 2 or not np.all(np.isfinite(time)):
        raise InputError(path, "column time", "at least two finite time stamps")
    dt = float(np.median(np.diff(time)))
    if dt <= 0 or np.max(np.abs(np.diff(time) - dt)) > time_step_tolerance(time, dt, np.dtype(np.float64)):
        raise InputError(path, "column time", "a uniform time grid in s (resample before importing)")
    return frame, dt, units


def _units(path: Path, columns: list[str], given: dict[str, str]) -> dict[str, str]:
    """The unit of every column: the contract's for its channels (a different one given is bad input), else given."""
    for name in given:
        if name not in columns:
            raise InputError(path, f"--unit {name}", f"a column of the CSV ({', '.join(columns)})")
    units = {}
    for name in columns:
        if name in ALIGNED_UNITS:
            if given.get(name, ALIGNED_UNITS[name]) != ALIGNED_UNITS[name]:
                raise InputError(path, f"column {name}", f"unit {ALIGNED_UNITS[name]!r} (contract section 1), "
                                                         f"got {given[name]!r}")
            units[name] = ALIGNED_UNITS[name]
        elif name in given:
            units[name] = given[name]
        else:
            raise InputError(path, f"column {name}", f"one of the contract's channels {sorted(ALIGNED_UNITS)}, or a "
                                                     "channel with its unit (--unit NAME=UNIT or a second header line)")
    return units


def run(args: argparse.Namespace) -> int:
    required = tuple(resolve_model(args.model).required_channels()) if args.model else REQUIRED
    frame, dt, units = read_csv(Path(args.csv), args.dt, parse_units(args.unit), required)
    write_run(args.out, frame, dt, protocol="imported", units=units)
    print(f"{args.out}: {len(frame)} samples at dt={dt:g} s, {len(frame.columns)} channels")
    return 0
