"""`benchlab import DATA.csv|DATA.mf4 --out RUN.h5 [--dt S] [--mapping MAP.toml] [--unit NAME=UNIT …]
[--model FILE.toml|linear|nonlinear]`: a CSV or an MDF file becomes a run file (contract sections 1 and 6). An MDF
file is read by benchlab.importing.mdf (channels by name or mapping, onto the grid --dt); the CSV reader is here.

Columns with the contract's /aligned names are in the contract's units unless their unit is given, in any spelling
of any unit of that dimension (`°C`, `K`, `Nm`, `1/min`, …: converted by benchlab.units); any other column needs
its unit. A unit is given by the column's title (`name [unit]`, what `benchlab export --to X.csv` writes), a second
header line of units or `--unit NAME=UNIT`. Without a `time` column, `--dt S` gives the grid. The CSV must hold
the clutch channels of section 1, or with `--model` the channels that model names.

The separator is the one of `,` `;` TAB that the header line holds (or `--sep`); with `;` or TAB a decimal
comma is read as a number when the data holds commas (German spreadsheets: `21,5;1500`), or as `--decimal`
says.
"""

from __future__ import annotations

import argparse
import io
import re
from pathlib import Path
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.bounds import MAX_CSV_COLUMNS, MAX_RUN_DURATION_S
from benchlab.errors import InputError, read_document
from benchlab.interrupts import interrupts_held
from benchlab.provenance import IMPORTED
from benchlab.model.names import MODEL_HELP
from benchlab.outputs import check_output

if TYPE_CHECKING:
    import pandas as pd

NAME = "import"
HELP = "convert a CSV or an MDF file (contract channel names, a mapping, any channel with its unit) into a run file"
SEPARATORS = {",": ",", ";": ";", "tab": "\t"}
#: What asammdf reads (benchlab.importing.mdf.SUFFIXES, kept here so that `--help` loads no asammdf).
MDF_SUFFIXES = (".mf4", ".mdf", ".dat")
#: A column title with its unit, `T_flywheel [degC]`.
TITLE_WITH_UNIT = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\]]*)\]$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("csv", metavar="DATA", help="CSV file, one column per channel, header = channel names or "
                                                    "`name [unit]` (optionally a second header line of units); or "
                                                    "an MDF file (.mf4, .mdf, .dat) with --dt")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="run file to write")
    parser.add_argument("--dt", type=cliargs.positive_float("a time step in s", MAX_RUN_DURATION_S),
                        help="time step in s of a CSV without a time column (one row per step); an MDF "
                             "file's grid (required for MDF)")
    parser.add_argument("--unit", type=cliargs.name_values, action="extend", default=[], metavar="NAME=UNIT[,...]",
                        help="the unit of each column beyond the contract's channels, repeatable or separated by "
                             "commas, e.g. --unit IqFbk=A,speed=rpm")
    parser.add_argument("--model", help=f"{MODEL_HELP}: the CSV must hold the channels it names "
                                        "(default: the clutch channels of contract section 1)")
    parser.add_argument("--sep", choices=tuple(SEPARATORS), help="column separator (default: the one in the header)")
    parser.add_argument("--decimal", choices=(".", ","),
                        help="decimal mark (default: ',' where the separator is ';' or tab and the data holds commas)")
    parser.add_argument("--mapping", metavar="MAP.toml", help="an MDF file's channels: run-file channel = source "
                                                              "channel, with group, unit, scale, offset, rule "
                                                              "(benchlab/importing/mapping.py)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file (a regular file)")


def parse_units(items: list[str]) -> dict[str, str]:
    """`NAME=UNIT` options as a dict; bad input names the item."""
    units = {}
    for item in items:
        name, sep, unit = (part.strip() for part in item.partition("="))
        if not sep or not name or not unit:
            raise InputError("--unit", item, "NAME=UNIT, e.g. IqFbk=A")
        units[name] = unit
    return units


def _is_number(text: object, decimal: str = ".") -> bool:
    try:
        float(str(text).replace(decimal, "."))
    except ValueError:
        return False
    return True


def _dialect(text: str, sep: str | None, decimal: str | None) -> tuple[str, str]:
    """Separator and decimal mark: given, or the separator the header holds most of and the decimal that fits."""
    header, _, body = text.partition("\n")
    sep = SEPARATORS[sep] if sep else max(SEPARATORS.values(), key=header.count)
    if decimal is None:
        decimal = "," if sep != "," and "," in body else "."
    return sep, decimal


def _check_width(path: Path, text: str, sep: str) -> None:
    """At most MAX_CSV_COLUMNS columns, counted on the header line before any row is parsed."""
    columns = text.partition("\n")[0].count(sep) + 1
    if columns > MAX_CSV_COLUMNS:
        raise InputError(path, "header", f"at most {MAX_CSV_COLUMNS} columns (channels), got {columns}")


def _channel_names(titles: list[str]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """Column titles to channel names, the units the titles give (`name [unit]`) and each name's title."""
    names, units, shown = [], {}, {}
    for title in (str(t).strip() for t in titles):
        match = TITLE_WITH_UNIT.match(title)
        name = match["name"] if match else title
        if match and match["unit"].strip():
            units[name] = match["unit"].strip()
        names.append(name)
        shown[name] = title
    return names, units, shown


def read_csv(path: Path, dt: float | None = None, units: dict[str, str] | None = None,
             required: tuple[str, ...] | None = None, sep: str | None = None,
             decimal: str | None = None) -> tuple[pd.DataFrame, float, dict[str, str]]:
    """Read and check the CSV: required columns (default: the clutch channels, REQUIRED), a unit for every column,
    numeric values, a uniform time grid (or `dt`); return frame, dt and the units."""
    import numpy as np
    import pandas as pd

    from benchlab.runfile import ALIGNED_UNITS, REQUIRED, time_step_tolerance, unmeasurable_sample
    from benchlab.runfile.schema import time_stamp_problem
    from benchlab.units import to_stored

    required = REQUIRED if required is None else required
    # a spreadsheet's byte-order mark is not part of the header (utf-8-sig)
    text = read_document(path, "CSV file", str, (), "a CSV table", encoding="utf-8-sig")
    try:
        sep, decimal = _dialect(text, sep, decimal)
        _check_width(path, text, sep)
        frame = pd.read_csv(io.StringIO(text), sep=sep, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(path, "file", f"a CSV table ({str(exc).splitlines()[0]})") from None
    names, title_units, titles = _channel_names(list(frame.columns))
    frame.columns = names
    first_line = 2
    if len(frame) and not any(_is_number(v, decimal) for v in frame.iloc[0]):  # a second header line: the units
        header_units = {c: str(u).strip() for c, u in zip(frame.columns, frame.iloc[0]) if str(u).strip()}
        frame = frame.iloc[1:].reset_index(drop=True)
        first_line = 3
    else:
        header_units = {}
    units = _units(path, list(frame.columns), {**title_units, **header_units, **dict(units or {})})
    if dt is not None and "time" in frame.columns:
        raise InputError(path, "column time", "no time column with --dt (one or the other gives the grid)")
    if dt is None and "time" not in frame.columns:
        raise InputError(path, "column time", "a time column in s, or --dt S for one row per step")
    for name in frame.columns:
        text = frame[name].astype(str).str.strip()
        if decimal != ".":
            text = text.str.replace(decimal, ".", regex=False)
        values = pd.to_numeric(text.replace({"": np.nan, "nan": np.nan, "NaN": np.nan}), errors="coerce")
        bad = values.isna() & ~text.isin(["", "nan", "NaN"])
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(path, f"column {name}, line {row + first_line}", f"a number, got {frame[name].iloc[row]!r}")
        frame[name], units[name] = to_stored(path, f"column {titles[name]}", name, values.to_numpy(np.float64),
                                             units[name])
        if name != "time" and (problem := unmeasurable_sample(name, units[name], frame[name].to_numpy())):
            raise InputError(path, f"column {name}, line {problem[0] + first_line}", f"{problem[1]}, got {problem[2]!r}")
    for name in ("time",) + tuple(required):
        if name not in frame.columns and not (name == "time" and dt is not None):
            raise InputError(path, f"column {name}", f"a required channel in {ALIGNED_UNITS.get(name, 'its unit')} "
                                                     "(missing)")
    if dt is not None:
        frame.insert(0, "time", np.arange(len(frame)) * dt)
        units["time"] = "s"
    time = frame["time"].to_numpy()
    if len(time) < 2 or not np.all(np.isfinite(time)):
        raise InputError(path, "column time", "at least two finite time stamps")
    if problem := time_stamp_problem(time):
        raise InputError(path, "column time", problem)
    dt = float(np.median(np.diff(time)))
    if dt <= 0 or np.max(np.abs(np.diff(time) - dt)) > time_step_tolerance(time, dt, np.dtype(np.float64)):
        raise InputError(path, "column time", "a uniform time grid in s (resample before importing)")
    return frame, dt, units


def _units(path: Path, columns: list[str], given: dict[str, str]) -> dict[str, str]:
    """The unit of every column as the file gives it: given, else the contract's for its channels."""
    from benchlab.runfile import ALIGNED_UNITS

    for name in given:
        if name not in columns:
            raise InputError(path, f"--unit {name}", f"a column of the CSV ({', '.join(columns)})")
    units = {}
    for name in columns:
        if name in given or name in ALIGNED_UNITS:
            units[name] = given.get(name, ALIGNED_UNITS.get(name))
        else:
            raise InputError(path, f"column {name}", f"one of the contract's channels {sorted(ALIGNED_UNITS)}, or a "
                                                     "channel with its unit (--unit NAME=UNIT or a second header line)")
    return units


def _read_mdf(args: argparse.Namespace, required: tuple[str, ...] | None) -> tuple[pd.DataFrame, dict, dict]:
    """An MDF file's channels on the grid --dt, with the required ones (default: the clutch channels)."""
    from benchlab.importing.mapping import read_mapping
    from benchlab.importing.mdf import read_mdf
    from benchlab.runfile import REQUIRED

    for flag, given in (("--unit", args.unit), ("--sep", args.sep), ("--decimal", args.decimal)):
        if given:
            raise InputError(args.csv, flag, "nothing for an MDF file (units and scales go in --mapping)")
    if args.dt is None:
        raise InputError(args.csv, "--dt", "the grid step in s for an MDF file's channels, e.g. --dt 0.01")
    frame, units, attrs = read_mdf(args.csv, read_mapping(args.mapping) if args.mapping else [], args.dt)
    for name in REQUIRED if required is None else required:
        if name not in frame.columns:
            raise InputError(args.csv, f"channel {name}", "a required channel: a channel of that name, or one "
                                                          "mapped to it in --mapping")
    return frame, units, attrs


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.model.catalog import resolve_model
        from benchlab.runfile import write_run  # and pandas, for read_csv
    required = tuple(resolve_model(args.model).required_channels()) if args.model else None
    check_output(args.out, "--out", args.force, inputs=[args.csv], run_file=True)
    if Path(args.csv).suffix.lower() in MDF_SUFFIXES:
        frame, units, attrs = _read_mdf(args, required)
        dt = args.dt
    else:
        if args.mapping:
            raise InputError(args.csv, "--mapping", f"an MDF file ({', '.join(MDF_SUFFIXES)}); a CSV names its "
                                                    "channels in its header")
        frame, dt, units = read_csv(Path(args.csv), args.dt, parse_units(args.unit), required, args.sep,
                                    args.decimal)
        attrs = {"source_file": Path(args.csv).name}
    write_run(args.out, frame, dt, protocol="imported", units=units, attrs={**attrs, "bench": IMPORTED})
    print(f"{args.out}: {len(frame)} samples at dt={dt:g} s, {len(frame.columns)} channels")
    return 0
