"""`benchlab import DATA… --out RUN.h5 [--dt S] [--mapping MAP.toml] [--dbc FILE.dbc] [--offset FILE=S]
[--unit NAME=UNIT …] [--model FILE.toml|linear|nonlinear]`: a CSV, an MDF file or a CAN log, or several of them
merged on one clock, becomes a run file (contract sections 1 and 6). MDF files are read by benchlab.importing.mdf,
CAN logs by benchlab.importing.canlog (channels by name or mapping), merged onto the grid --dt with their raw
streams by benchlab.importing.sources; the CSV reader is here.

Columns with the contract's /aligned names are in the contract's units unless their unit is given, in any spelling
of any unit of that dimension (`°C`, `K`, `Nm`, `1/min`, …: converted by benchlab.units); any other column needs
its unit. A unit is given by the column's title (`name [unit]`, what `benchlab export --to X.csv` writes), a second
header line of units or `--unit NAME=UNIT`. Without a `time` column, `--dt S` gives the grid. The CSV must hold
the clutch channels of section 1, or with `--model` the channels that model names.

The separator is the one of `,` `;` TAB that the header line holds (or `--sep`); with `;` or TAB a decimal
comma is read as a number when the data holds commas (German spreadsheets: `21,5;1500`), or as `--decimal`
says.

With `--mapping MAP.toml` (benchlab.importing.mapping, the format MDF files and CAN logs use) a CSV's own column
names become the run file's: `T_air = "T_Luft"` takes the column `T_Luft [°C]` (by its name or whole title),
its unit from the title unless the entry gives one, scaled as the entry says; `time = "Zeit"` names the time column.
"""

from __future__ import annotations

import argparse
import io
import json
import re
from dataclasses import replace
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

    from benchlab.importing.mapping import Mapped
    from benchlab.importing.sources import Input, Merged

NAME = "import"
HELP = ("convert a CSV, an MDF file or a CAN log (.blf, .asc, .trc, .log, decoded with a DBC), or several merged on "
        "one clock, into a run file (the channel names of docs/contract.md §1, a mapping, any channel with its unit)")
SEPARATORS = {",": ",", ";": ";", "tab": "\t"}
#: What asammdf reads, and python-can's LogReader (benchlab.importing.canlog.CAN_LOG_SUFFIXES: `.mf4` where it
#: holds CAN bus logging), kept here so that `--help` loads neither.
MDF_SUFFIXES = (".mf4", ".mdf", ".dat")
CAN_SUFFIXES = (".blf", ".asc", ".trc", ".log", ".mf4")
#: A column title with its unit, `T_flywheel [degC]`.
TITLE_WITH_UNIT = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\]]*)\]$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("inputs", nargs="+", metavar="DATA",
                        help="CSV file, one column per channel, header = channel names or `name [unit]` (optionally "
                             "a second header line of units); an MDF file (.mf4, .mdf, .dat); a CAN log (.blf, .asc, "
                             ".trc, .log, .mf4 bus logging) decoded with --dbc's database. Several are merged into one run on one clock "
                             "(then --dt is the grid)")
    parser.add_argument("--out", required=True, type=cliargs.output_file, help="run file to write")
    parser.add_argument("--dt", type=cliargs.positive_float("a time step in s", MAX_RUN_DURATION_S),
                        help="time step in s of a CSV without a time column (one row per step); the grid of an MDF "
                             "file, a CAN log or several inputs (required for them)")
    parser.add_argument("--unit", type=cliargs.name_values, action="extend", default=[], metavar="NAME=UNIT[,...]",
                        help="the unit of each column beyond the contract's channels, repeatable or separated by "
                             "commas, e.g. --unit IqFbk=A,speed=rpm")
    parser.add_argument("--model", help=f"{MODEL_HELP}: the CSV must hold the channels it names "
                                        "(default: the clutch channels of docs/contract.md §1)")
    parser.add_argument("--sep", choices=tuple(SEPARATORS), metavar="{',',';',tab}",
                        help="a CSV's column separator: ',' ';' or tab (default: the one in the header)")
    parser.add_argument("--decimal", choices=(".", ","), metavar="{'.',','}",
                        help="decimal mark (default: ',' where the separator is ';' or tab and the data holds commas)")
    parser.add_argument("--mapping", metavar="MAP.toml", help="a CSV's columns, an MDF file's channels or a CAN "
                                                              "log's signals: run-file channel = source channel, "
                                                              "with group, unit, scale, offset, rule; time = a "
                                                              "CSV's time column (docs/runfile.md)")
    parser.add_argument("--dbc", metavar="FILE.dbc", help="the CAN database of a CAN log (default: drivers/bench.dbc)")
    parser.add_argument("--offset", action="append", default=[], metavar="FILE=S",
                        help="add S seconds to the time stamps of the input FILE (its clock ran S s behind the "
                             "others'); repeatable")
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


def _apply_mapping(path: Path, names: list[str], units: dict[str, str], titles: dict[str, str],
                   mapped: list[Mapped]) -> tuple[list[str], dict[str, str], dict[str, Mapped]]:
    """The columns renamed as the mapping says (a source matched by a column's name or whole title), their units (the entry's before the title's) and each renamed
    column's entry; InputError naming an entry whose source is no column."""
    renamed, units, applied = list(names), dict(units), {}
    for entry in mapped:
        at = next((i for i, name in enumerate(names) if entry.source in (name, titles[name])), None)
        if at is None:
            raise InputError(path, f"mapping channels.{entry.channel}", f"a column of the CSV (no column "
                                                                        f"{entry.source!r})")
        if entry.channel in renamed and renamed.index(entry.channel) != at:
            raise InputError(path, f"channel {entry.channel} ← {entry.source}", f"one column named {entry.channel} "
                                                                                "(the CSV holds one itself)")
        source = names[at]
        renamed[at] = entry.channel
        title_unit = units.pop(source, None)
        unit = title_unit if entry.unit is None else entry.unit
        if unit is not None:
            units[entry.channel] = unit
        titles[entry.channel] = titles[source]
        applied[entry.channel] = entry
    return renamed, units, applied


def read_csv(path: Path, dt: float | None = None, units: dict[str, str] | None = None,
             required: tuple[str, ...] | None = None, sep: str | None = None,
             decimal: str | None = None,
             mapped: list[Mapped] | None = None) -> tuple[pd.DataFrame, float, dict[str, str]]:
    """Read and check the CSV: its columns renamed by `mapped` (a mapping file's entries), required columns
    (default: the clutch channels, REQUIRED), a unit for every column, numeric values, a uniform time grid (or
    `dt`); return frame, dt and the units (the frame's attrs: `encoding`, `mapped_from` channel -> source)."""
    import numpy as np
    import pandas as pd

    from benchlab.importing.mapping import missing_channels
    from benchlab.runfile import REQUIRED, time_step_tolerance, unmeasurable_sample
    from benchlab.runfile.schema import time_stamp_problem
    from benchlab.units import to_stored

    required = REQUIRED if required is None else required
    text, encoding = csv_text(path)
    try:
        sep, decimal = _dialect(text, sep, decimal)
        _check_width(path, text, sep)
        frame = pd.read_csv(io.StringIO(text), sep=sep, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(path, "file", f"a CSV table ({str(exc).splitlines()[0]})") from None
    names, title_units, titles = _channel_names(list(frame.columns))
    offered = list(names)
    names, title_units, applied = _apply_mapping(path, names, title_units, titles, mapped or [])
    frame.columns = names
    first_line = 2
    if len(frame) and not any(_is_number(v, decimal) for v in frame.iloc[0]):  # a second header line: the units
        header_units = {c: str(u).strip() for c, u in zip(frame.columns, frame.iloc[0]) if str(u).strip()}
        frame = frame.iloc[1:].reset_index(drop=True)
        first_line = 3
    else:
        header_units = {}
    units = _units(path, list(frame.columns), {**title_units, **header_units, **dict(units or {})})
    missing = [name for name in dict.fromkeys(("time",) + tuple(required))
               if name not in frame.columns and not (name == "time" and dt is not None)]
    if len(missing) > 1 or (missing and missing[0] != "time"):
        raise missing_channels(path, "column", missing, offered)
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
        entry = applied.get(name)
        numbers = values.to_numpy(np.float64) * (entry.scale if entry else 1.0) + (entry.offset if entry else 0.0)
        frame[name], units[name] = to_stored(path, f"column {titles[name]}", name, numbers, units[name])
        if name != "time" and (problem := unmeasurable_sample(name, units[name], frame[name].to_numpy())):
            raise InputError(path, f"column {name}, line {problem[0] + first_line}", f"{problem[1]}, got {problem[2]!r}")
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
    frame.attrs["encoding"] = encoding
    frame.attrs["mapped_from"] = {channel: entry.source for channel, entry in applied.items()}
    return frame, dt, units


def csv_text(path: Path) -> tuple[str, str]:
    """The CSV's text and the encoding it was read in: UTF-8 first (a byte-order mark is not part of the header),
    else Windows-1252, what German Excel saves (`°` as the byte 0xB0)."""
    try:
        return read_document(path, "CSV file", str, (), "a CSV table", encoding="utf-8-sig"), "UTF-8"
    except InputError:
        if not path.is_file():
            raise
    return read_document(path, "CSV file", str, (), "a CSV table in UTF-8 or Windows-1252",
                         encoding="cp1252"), "Windows-1252"


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


def parse_offsets(items: list[str], inputs: list[str]) -> dict[Path, float]:
    """`FILE=S` options as {input path: seconds}; FILE is an input as given or its file name."""
    import math

    offsets = {}
    for item in items:
        name, sep, value = (part.strip() for part in item.rpartition("="))
        try:
            seconds = float(value)
        except ValueError:
            seconds = math.nan
        match = [Path(i) for i in inputs if name in (i, Path(i).name)]
        if not sep or len(match) != 1 or not (math.isfinite(seconds) and abs(seconds) <= MAX_RUN_DURATION_S):
            raise InputError("--offset", item, f"FILE=SECONDS with FILE one of the inputs ({', '.join(inputs)}) and "
                                               f"|SECONDS| <= {MAX_RUN_DURATION_S:g}")
        offsets[match[0]] = seconds
    return offsets


def _csv_input(args: argparse.Namespace, path: Path, mapped: list[Mapped]) -> Input:
    """A CSV among several inputs: every column (renamed as `mapped` says) at its time column's stamps (or one
    row per --dt)."""
    from benchlab.importing.sources import Input, SourceChannel

    text = csv_text(path)[0]
    header = text.partition("\n")[0]
    names, _, titles = _channel_names(header.split(_dialect(text, args.sep, args.decimal)[0]))
    mapped = [entry for entry in mapped if entry.source in set(names) | set(titles.values())]  # the CSV's own
    timed = "time" in names or any(entry.channel == "time" for entry in mapped)
    frame, _, units = read_csv(path, None if timed else args.dt, parse_units(args.unit), (), args.sep, args.decimal,
                               mapped)
    time, sources = frame["time"].to_numpy(), frame.attrs["mapped_from"]
    rules = {entry.channel: entry.rule for entry in mapped if entry.rule}
    return Input(path, [SourceChannel(name, time, frame[name].to_numpy(), units[name],
                                      rules.get(name, "hold" if name == "clutch_state" else "interpolate"),
                                      f"{path.name}: column {sources.get(name, name)}", path.stem,
                                      sources.get(name, name), frame[name].to_numpy(), units[name])
                        for name in frame.columns if name != "time"],
                 stream_attrs={path.stem: {"source_file": path.name}}, offered=tuple(frame.columns))


def _read_inputs(args: argparse.Namespace, required: tuple[str, ...] | None) -> Merged:
    """Every input (MDF, CAN log, CSV) read and merged on the grid --dt, with the required channels (default: the
    clutch channels)."""
    from benchlab.drivetrain import DrivetrainFacts
    from benchlab.importing.canlog import derive_bench_channels, read_foreign
    from benchlab.importing.mapping import missing_channels, read_mapping
    from benchlab.importing.sources import merge
    from benchlab.runfile import REQUIRED
    from drivers.can_signals import BENCH_DBC

    where = args.inputs[0] if len(args.inputs) == 1 else "inputs"
    if not any(Path(i).suffix.lower() not in MDF_SUFFIXES + CAN_SUFFIXES for i in args.inputs):
        for flag, given in (("--unit", args.unit), ("--sep", args.sep), ("--decimal", args.decimal)):
            if given:
                raise InputError(where, flag, "nothing for an MDF file or a CAN log (units and scales go in "
                                              "--mapping)")
    if args.dt is None:
        raise InputError(where, "--dt", "the grid step in s for an MDF file's channels, a CAN log's signals or "
                                        "several inputs, e.g. --dt 0.01")
    mapped = read_mapping(args.mapping) if args.mapping else []
    timed = [entry for entry in mapped if entry.channel == "time"]
    if timed and all(Path(i).suffix.lower() in MDF_SUFFIXES + CAN_SUFFIXES for i in args.inputs):
        raise InputError(args.mapping, "channels.time", "a CSV's time column (an MDF file's and a CAN log's time "
                                                        "stamps are their own)")
    inputs = []
    for name in args.inputs:
        path = Path(name)
        if path.suffix.lower() in MDF_SUFFIXES + CAN_SUFFIXES:
            inputs.append(read_foreign(path, [e for e in mapped if e not in timed], args.dbc or BENCH_DBC,
                                       DrivetrainFacts().gear_ratio))
        else:
            inputs.append(_csv_input(args, path, mapped))
    required = REQUIRED if required is None else required
    offered = [name for i in inputs for name in i.offered]
    found = {c.raw_name for i in inputs for c in i.channels} | {c.channel for i in inputs for c in i.channels}
    for entry in mapped:
        if entry in timed:
            continue
        if entry.source not in found and entry.source.rpartition(".")[2] not in found:
            raise InputError(where, f"channel {entry.channel} ← {entry.source}", "a channel of the inputs (not "
                                                                                 "found)")
    if not any(i.channels for i in inputs):
        raise missing_channels(where, "channel", [name for name in required if name != "time"], offered)
    merged = merge(inputs, args.dt, parse_offsets(args.offset, args.inputs))
    frame = derive_bench_channels(merged.frame)
    sources = {**{name: {"from": "the clutch actuator's clamp state, as the bench derives it"}
                  for name in frame.columns if name not in merged.frame.columns}, **merged.sources}
    missing = [name for name in required if name not in frame.columns]
    if missing:
        raise missing_channels(where, "channel", missing, offered)
    return replace(merged, frame=frame, sources=sources)


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.importing.mapping import read_mapping
        from benchlab.model.catalog import resolve_model
        from benchlab.runfile import write_run  # and pandas, for read_csv
    required = tuple(resolve_model(args.model).required_channels()) if args.model else None
    check_output(args.out, "--out", args.force, inputs=args.inputs, run_file=True)
    if len(args.inputs) == 1 and Path(args.inputs[0]).suffix.lower() not in MDF_SUFFIXES + CAN_SUFFIXES:
        if args.dbc or args.offset:
            raise InputError(args.inputs[0], "--dbc" if args.dbc else "--offset",
                             "a CAN log or several inputs; a CSV's channels are its columns")
        mapped = read_mapping(args.mapping) if args.mapping else []
        frame, dt, units = read_csv(Path(args.inputs[0]), args.dt, parse_units(args.unit), required, args.sep,
                                    args.decimal, mapped)
        write_run(args.out, frame, dt, protocol="imported", units=units,
                  attrs={"source_file": Path(args.inputs[0]).name, "bench": IMPORTED})
        if frame.attrs.get("encoding", "UTF-8") != "UTF-8":
            print(f"{args.inputs[0]}: read as {frame.attrs['encoding']} (not UTF-8)")
    else:
        merged = _read_inputs(args, required)
        frame, dt = merged.frame, args.dt
        write_run(args.out, frame, dt, protocol="imported", units=merged.units, attrs={**merged.attrs, "bench": IMPORTED},
                  sources=merged.sources, raw=merged.raw)
        for what, n in json.loads(merged.attrs.get("import_skipped", "{}")).items():
            print(f"{what}: {n} skipped")
    print(f"{args.out}: {len(frame)} samples at dt={dt:g} s, {len(frame.columns)} channels")
    return 0
