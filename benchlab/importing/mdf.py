"""An MDF file (`.mf4`, `.mdf`, `.dat`: whatever asammdf reads) as the channels of a run file on one grid.

Channels are picked by a mapping file (benchlab.importing.mapping) and, where it names none, by the contract's
names the MDF holds (what `benchlab export --to X.mf4` writes). Each is read with its own master (time stamps),
its invalidation bits as NaN, scaled as the mapping says, converted to the contract's unit (benchlab.units) and put
on the grid `--dt` by its rule (benchlab.importing.grid). The MDF's start time (plus the first sample's offset)
becomes `created_utc`, its header comment `source_comment`.
"""

from __future__ import annotations

import json
import os
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchlab.bounds import MAX_IMPORT_ROWS, MAX_RUN_DURATION_S
from benchlab.errors import InputError
from benchlab.importing.grid import resample
from benchlab.importing.mapping import Mapped
from benchlab.runfile.schema import ALIGNED_UNITS, unmeasurable_sample
from benchlab.units import to_stored


def _open(path: Path) -> Any:
    """asammdf's MDF of `path`; InputError where it is missing or not an MDF file."""
    from asammdf import MDF

    if not path.is_file():
        raise InputError(path, "file", "an existing MDF file (not found)" if not path.exists() else "an MDF file")
    try:
        return MDF(path)
    except Exception as exc:  # asammdf raises anything from struct.error to MdfException on a file it cannot read
        raise InputError(path, "file", f"an MDF file asammdf reads ({type(exc).__name__}: {exc})") from None


def _location(path: Path, mdf: Any, entry: Mapped) -> tuple[int, int]:
    """(group, index) of the entry's source channel; InputError where it is absent or ambiguous."""
    found = [(g, i) for g, i in mdf.channels_db.get(entry.source, ()) if entry.group in (None, g)]
    field = f"channel {entry.channel} ← {entry.source}"
    if not found:
        where = f" in group {entry.group}" if entry.group is not None else ""
        raise InputError(path, field, f"a channel of the MDF file{where} (not found)")
    if len(found) > 1:
        raise InputError(path, field, f"one channel: groups {sorted({g for g, _ in found})} hold {entry.source!r}, "
                                      "say which with group in the mapping file")
    return found[0]


def _entries(mdf: Any, mapped: list[Mapped]) -> list[Mapped]:
    """The mapping's entries, then the contract's channels the MDF holds under their own names."""
    named = {m.channel for m in mapped}
    return mapped + [Mapped(name, name) for name in ALIGNED_UNITS
                     if name != "time" and name not in named and name in mdf.channels_db]


def _series(path: Path, mdf: Any, entry: Mapped) -> tuple[np.ndarray, np.ndarray, str, str]:
    """One source channel: time stamps, values in the run file's unit (invalid samples NaN), that unit, the rule."""
    group, index = _location(path, mdf, entry)
    sig = mdf.get(group=group, index=index, ignore_invalidation_bits=True)  # every sample, with its bit
    if sig.samples.dtype.kind in "SUO":  # an enum shown as its value table's texts: the numbers behind them
        sig = mdf.get(group=group, index=index, ignore_invalidation_bits=True, raw=True)
    field = f"channel {entry.channel} ← {entry.source}"
    if sig.samples.dtype.kind not in "iufb" or sig.samples.ndim != 1:
        raise InputError(path, field, f"a numeric channel, got samples of type {sig.samples.dtype}")
    values = sig.samples.astype(np.float64) * entry.scale + entry.offset
    if sig.invalidation_bits is not None:
        values[np.asarray(sig.invalidation_bits, dtype=bool)] = np.nan
    unit = entry.unit if entry.unit is not None else str(sig.unit or "")
    if not unit and entry.channel not in ALIGNED_UNITS:
        raise InputError(path, field, "a unit (the MDF file gives none): unit in the mapping file, \"1\" for a number")
    values, stored = to_stored(path, f"{field} [{unit}]", entry.channel, values, unit)
    if (problem := unmeasurable_sample(entry.channel, stored, values)) is not None:
        raise InputError(path, f"{field}, sample {problem[0]}", f"{problem[1]}, got {problem[2]!r}")
    held = entry.channel == "clutch_state" or sig.samples.dtype.kind in "iub"
    return np.asarray(sig.timestamps, dtype=np.float64), values, stored, entry.rule or ("hold" if held else
                                                                                         "interpolate")


def read_mdf(path: "str | os.PathLike[str]", mapped: list[Mapped], dt: float
             ) -> tuple[pd.DataFrame, dict[str, str], dict[str, str]]:
    """The MDF's chosen channels on a grid of step `dt` from the earliest sample to the latest: the frame (`time`
    first, from 0), each channel's stored unit, and the run file's root attributes it carries over."""
    path = Path(path)
    mdf = _open(path)
    try:
        series = {e.channel: (_series(path, mdf, e), e) for e in _entries(mdf, mapped)}
        start, comment = mdf.header.start_time, str(mdf.header.description or "")
    finally:
        mdf.close()
    if not series:
        raise InputError(path, "channels", "channels with the contract's names, or a mapping file (--mapping)")
    stamps = [s[0] for s, _ in series.values() if np.isfinite(s[0]).any()]
    t0 = min(float(np.nanmin(t)) for t in stamps) if stamps else 0.0
    span = max(float(np.nanmax(t)) for t in stamps) - t0 if stamps else 0.0
    if span > MAX_RUN_DURATION_S:
        raise InputError(path, "time stamps", f"a run of at most {MAX_RUN_DURATION_S:g} s, got {span:g} s")
    rows = int(np.floor(span / dt + 1e-9)) + 1
    if rows > MAX_IMPORT_ROWS:
        raise InputError(path, "--dt", f"a grid of at most {MAX_IMPORT_ROWS} rows over the file's {span:g} s, "
                                       f"got {rows} at dt={dt:g} s")
    time = np.arange(rows) * dt
    frame = pd.DataFrame({"time": time, **{name: resample(t - t0, v, time, rule)
                                           for name, ((t, v, _, rule), _) in series.items()}})
    units = {"time": "s", **{name: s[2] for name, (s, _) in series.items()}}
    picked = {name: {"source": e.source, "unit": s[2], "rule": s[3]} for name, (s, e) in series.items()}
    attrs = {"source_file": path.name, "source_comment": comment, "source_channels": json.dumps(picked),
             "created_utc": (start + timedelta(seconds=t0)).isoformat()}
    return frame, units, attrs
