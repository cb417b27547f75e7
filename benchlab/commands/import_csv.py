"""`benchlab import DATA.csv --out RUN.h5`: a CSV with the /aligned column names becomes a run file.

The separator is the one of `,` `;` TAB that the header line holds (or `--sep`); with `;` or TAB a decimal
comma is read as a number when the data holds commas (German spreadsheets: `21,5;1500`), or as `--decimal`
says. A header `name [unit]` (what `benchlab export --to X.csv` writes) is read as the channel `name`, and
its unit must be the contract's.
"""

from __future__ import annotations

import argparse
import io
import re
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab import cliargs
from benchlab.errors import InputError
from benchlab.runfile import ALIGNED_UNITS, REQUIRED, time_step_tolerance, unmeasurable_sample, write_run

NAME = "import"
HELP = "convert a CSV with the /aligned column names (contract units) into a run file"
SEPARATORS = {",": ",", ";": ";", "tab": "\t"}
#: A column title with its unit, `T_flywheel [degC]`.
TITLE_WITH_UNIT = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\]]*)\]$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("csv", help="CSV file, one column per channel, header = channel names (or `name [unit]`)")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="run file to write")
    parser.add_argument("--sep", choices=tuple(SEPARATORS), help="column separator (default: the one in the header)")
    parser.add_argument("--decimal", choices=(".", ","),
                        help="decimal mark (default: ',' where the separator is ';' or tab and the data holds commas)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --out file")


def _dialect(text: str, sep: str | None, decimal: str | None) -> tuple[str, str]:
    """Separator and decimal mark: given, or the separator the header holds most of and the decimal that fits."""
    header, _, body = text.partition("\n")
    sep = SEPARATORS[sep] if sep else max(SEPARATORS.values(), key=header.count)
    if decimal is None:
        decimal = "," if sep != "," and "," in body else "."
    return sep, decimal


def _channel_names(path: Path, titles: list[str]) -> list[str]:
    """Column titles to channel names; a unit in the title must be the channel's contract unit."""
    names = []
    for title in (str(t).strip() for t in titles):
        match = TITLE_WITH_UNIT.match(title)
        name = match["name"] if match else title
        if match and name in ALIGNED_UNITS and match["unit"].strip() != ALIGNED_UNITS[name]:
            raise InputError(path, f"column {title}", f"{name} in {ALIGNED_UNITS[name]}, got {match['unit']!r}")
        names.append(name)
    return names


def read_csv(path: Path, sep: str | None = None, decimal: str | None = None) -> tuple[pd.DataFrame, float]:
    """Read and check the CSV: required columns, numeric values, uniform time; return frame and dt."""
    if not path.exists():
        raise InputError(path, "file", "an existing CSV file (not found)")
    try:
        text = path.read_text(encoding="utf-8-sig")  # a spreadsheet's byte-order mark is not part of the header
        sep, decimal = _dialect(text, sep, decimal)
        frame = pd.read_csv(io.StringIO(text), sep=sep, decimal=decimal)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(path, "file", f"a CSV table ({str(exc).splitlines()[0]})") from None
    frame.columns = _channel_names(path, list(frame.columns))
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
    if Path(args.out).exists() and not args.force:
        raise InputError(args.out, "--out", "a new run file (it exists: --force to overwrite)")
    frame, dt = read_csv(Path(args.csv), args.sep, args.decimal)
    write_run(args.out, frame, dt, protocol="imported")
    print(f"{args.out}: {len(frame)} samples at dt={dt:g} s, {len(frame.columns)} channels")
    return 0
