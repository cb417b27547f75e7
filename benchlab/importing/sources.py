"""Inputs of `benchlab import` merged into one run: each input's channels at their own time stamps on one clock,
put on one grid by their rules, each source channel also kept raw under /raw as `benchlab run` keeps its streams.

The clock: an input that knows when its time 0 was (an MDF's header start time, a CAN log's UNIX time stamps) is
placed by it; one that does not (a CSV, a CAN log of relative stamps) starts at the earliest known start (at 0
where none is known). `--offset FILE=S` then adds S seconds to that input's stamps (a logger whose clock ran
S seconds behind). The run starts at the earliest sample of any input; `created_utc` is that instant where a
start is known.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.bounds import MAX_IMPORT_ROWS, MAX_RUN_DURATION_S
from benchlab.errors import InputError
from benchlab.importing.grid import resample
from benchlab.runfile.write import RawStream


@dataclass(frozen=True)
class SourceChannel:
    """One source channel as read: stamps (s, its input's clock), values in the unit the run file stores, the grid
    rule, where it came from (`origin`, for the dataset's description), and as the file held it (`raw_*`, the raw
    stream `stream` it belongs to: channels of one stream share their stamps)."""

    channel: str
    stamps: np.ndarray
    values: np.ndarray
    unit: str
    rule: str
    origin: str
    stream: str
    raw_name: str
    raw_values: np.ndarray
    raw_unit: str


@dataclass(frozen=True)
class Input:
    """One input file read: its channels, when its time 0 was (None: unknown), the root attributes it carries
    (comment, start), per raw stream its attributes (rate, bus, message, node), what was counted and skipped, and
    the channel names the file offers (what a mapping may name; shown when required channels are missing)."""

    path: Path
    channels: list[SourceChannel]
    start: datetime | None = None
    attrs: dict[str, str] = field(default_factory=dict)
    stream_attrs: dict[str, dict[str, object]] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    offered: tuple[str, ...] = ()


@dataclass(frozen=True)
class Merged:
    """The run built from the inputs: /aligned on the grid, units, root attributes, descriptions, /raw."""

    frame: pd.DataFrame
    units: dict[str, str]
    attrs: dict[str, str]
    sources: dict[str, dict]
    raw: tuple[RawStream, ...]


def _shifts(inputs: list[Input], offsets: dict[Path, float]) -> tuple[list[float], datetime | None]:
    """Per input the seconds added to its stamps to put them on the common clock, and that clock's time 0."""
    starts = [i.start for i in inputs if i.start is not None]
    zero = min(starts) if starts else None
    shifts = [((i.start - zero).total_seconds() if i.start is not None and zero is not None else 0.0)
              + offsets.get(i.path, 0.0) for i in inputs]
    return shifts, zero


def merge(inputs: list[Input], dt: float, offsets: dict[Path, float] | None = None) -> Merged:
    """The inputs' channels on one grid of step `dt` from the earliest sample to the latest (the first input
    holding a channel gives it), with their raw streams on the run's clock."""
    shifts, zero = _shifts(inputs, offsets or {})
    chosen: dict[str, tuple[SourceChannel, float, Input]] = {}
    for shift, source in zip(shifts, inputs):
        for c in source.channels:
            chosen.setdefault(c.channel, (c, shift, source))
    where = inputs[0].path if len(inputs) == 1 else "inputs"
    if not chosen:
        raise InputError(where, "channels", "channels with the contract's names, or a mapping file (--mapping)")
    finite = [c.stamps[np.isfinite(c.stamps)] + s for c, s, _ in chosen.values()]
    finite = [t for t in finite if len(t)]
    _check_one_run(where, inputs, shifts)
    t0 = min(float(t.min()) for t in finite) if finite else 0.0
    span = max(float(t.max()) for t in finite) - t0 if finite else 0.0
    rows = int(np.floor(span / dt + 1e-9)) + 1
    if rows > MAX_IMPORT_ROWS:
        raise InputError(where, "--dt", f"a grid of at most {MAX_IMPORT_ROWS} rows over the inputs' {span:g} s, "
                                        f"got {rows} at dt={dt:g} s")
    time = np.arange(rows) * dt
    frame = pd.DataFrame({"time": time, **{name: resample(c.stamps + s - t0, c.values, time, c.rule)
                                           for name, (c, s, _) in chosen.items()}})
    units = {"time": "s", **{name: c.unit for name, (c, _, _) in chosen.items()}}
    picked = {name: {"file": i.path.name, "source": c.raw_name, "unit": c.unit, "rule": c.rule}
              for name, (c, _, i) in chosen.items()}
    attrs = {"source_file": ", ".join(i.path.name for i in inputs), "source_channels": json.dumps(picked)}
    for i in inputs:
        attrs.update(i.attrs)
    if zero is not None:
        attrs["created_utc"] = (zero + timedelta(seconds=t0)).isoformat()
    skipped = {f"{i.path.name}: {what}": n for i in inputs for what, n in i.skipped.items() if n}
    if skipped:
        attrs["import_skipped"] = json.dumps(skipped)
    sources = {name: {"from": c.origin} for name, (c, _, _) in chosen.items()}
    return Merged(frame, units, attrs, sources, _raw(inputs, shifts, t0))


def _check_one_run(where: "str | Path", inputs: list[Input], shifts: list[float]) -> None:
    """InputError where the inputs' samples on the common clock (every channel, the ones another input gives too)
    span more than a run lasts: clocks that far apart are not one run."""
    ends = [(float(t.min()) + shift, float(t.max()) + shift, source.path)
            for shift, source in zip(shifts, inputs) for c in source.channels
            if len(t := c.stamps[np.isfinite(c.stamps)])]
    if not ends:
        return
    first, last = min(ends, key=lambda e: e[0]), max(ends, key=lambda e: e[1])
    span = last[1] - first[0]
    if span > MAX_RUN_DURATION_S:
        apart = (f"{span:g} s from the start of {first[2].name} to the end of {last[2].name}"
                 if first[2] != last[2] else f"{span:g} s")
        raise InputError(where, "time stamps", f"one run of at most {MAX_RUN_DURATION_S:g} s, got {apart} (clocks "
                                               "that far apart are not one run: --offset FILE=S if a logger's clock "
                                               "was wrong)")


def _raw(inputs: list[Input], shifts: list[float], t0: float) -> tuple[RawStream, ...]:
    """Every input's source channels as the file held them, one stream per source group, on the run's clock."""
    streams: dict[str, tuple[np.ndarray, dict, dict]] = {}
    for shift, source in zip(shifts, inputs):
        for c in source.channels:
            _, columns, _ = streams.setdefault(c.stream, (c.stamps + shift - t0, {},
                                                          dict(source.stream_attrs.get(c.stream, {}))))
            columns[c.raw_name] = (c.raw_values, c.raw_unit, f"{c.origin}, as the file held it")
    return tuple(RawStream(name, time, columns, attrs) for name, (time, columns, attrs) in streams.items())
