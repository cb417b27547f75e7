"""A run file's time-stamped groups besides /aligned, as stored: every /raw/<stream>, /events, /simulated and
/estimated,
cut at the progress record (what lies beyond it in a file still being written is allocated space, not data);
with the acquisition layout and /aligned's dataset descriptions (what `benchlab export` carries)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from benchlab.errors import InputError
from benchlab.runfile.read import open_run, read_progress, text


@dataclass(frozen=True)
class StoredColumn:
    """One dataset of a group: its values (valid rows, stored order), unit and `description` attribute ("")."""

    name: str
    values: np.ndarray
    unit: str
    description: str


@dataclass(frozen=True)
class StoredGroup:
    """A group of 1-D datasets sharing `time` (s): `path` as in the file (`/raw/can_drive`), `name` its last part."""

    path: str
    name: str
    time: np.ndarray
    columns: tuple[StoredColumn, ...]
    attrs: dict[str, str]


@dataclass(frozen=True)
class StoredStreams:
    """Everything of a run file beyond /aligned's values that an export shows (see the module docstring)."""

    progress: dict[str, float]  # empty for a file without a progress record (every row valid)
    layout: dict[str, Any]  # /acquire's `layout` (streams, where each /aligned channel comes from); {} without one
    descriptions: dict[str, str]  # /aligned channel -> its `description` attribute, where it has one
    groups: tuple[StoredGroup, ...]


def load_streams(path: "str | os.PathLike[str]") -> StoredStreams:
    """The run file's time-stamped groups, layout and descriptions; InputError naming a malformed dataset."""
    path = Path(path)
    with open_run(path) as f:
        progress = read_progress(f) if "acquire/progress" in f else {}
        layout = f["acquire"].attrs.get("layout", "{}") if isinstance(f.get("acquire"), h5py.Group) else "{}"
        aligned = f["aligned"] if isinstance(f.get("aligned"), h5py.Group) else {}
        descriptions = {name: text(ds.attrs["description"]) for name, ds in aligned.items()
                        if isinstance(ds, h5py.Dataset) and "description" in ds.attrs}
        groups = tuple(_read_group(path, f[group_path], group_path, rows)
                       for group_path, rows in _timestamped_groups(f, progress))
    return StoredStreams(progress, json.loads(text(layout)), descriptions, groups)


def _timestamped_groups(f: h5py.File, progress: dict[str, float]) -> list[tuple[str, int | None]]:
    """(HDF5 path, valid rows or None) of every time-stamped group besides /aligned."""
    out: list[tuple[str, int | None]] = []
    if isinstance(f.get("raw"), h5py.Group):
        for stream, group in f["raw"].items():
            if isinstance(group, h5py.Group) and "time" in group:
                rows = progress.get(f"rows/{stream}")
                out.append((f"/raw/{stream}", None if rows is None else int(rows)))
    for name, counter in (("events", "event_rows"), ("simulated", None), ("estimated", None)):
        if isinstance(f.get(name), h5py.Group) and "time" in f[name]:
            rows = progress.get(counter) if counter else None
            out.append((f"/{name}", None if rows is None else int(rows)))
    return out


def _read_group(path: Path, group: h5py.Group, group_path: str, limit: int | None) -> StoredGroup:
    """One group's valid rows (the first `limit`, all if None), every dataset checked: 1-D, as long as `time`,
    with a unit, numbers or byte strings."""
    time_ds = group["time"]
    if time_ds.ndim != 1 or not np.issubdtype(time_ds.dtype, np.number):
        raise InputError(path, f"{group_path}/time", "a 1-D numeric dataset of time stamps in s")
    n = time_ds.shape[0] if limit is None else min(limit, time_ds.shape[0])
    columns = []
    for column, ds in group.items():
        if column == "time" or not isinstance(ds, h5py.Dataset):
            continue
        if ds.ndim != 1 or ds.shape[0] != time_ds.shape[0]:
            raise InputError(path, f"{group_path}/{column}", f"a 1-D dataset as long as {group_path}/time")
        if "units" not in ds.attrs:
            raise InputError(path, f"{group_path}/{column}.units", "a units attribute")
        if not (np.issubdtype(ds.dtype, np.number) or ds.dtype.kind == "S"):
            raise InputError(path, f"{group_path}/{column}", "numbers or byte strings")
        description = text(ds.attrs["description"]) if "description" in ds.attrs else ""
        columns.append(StoredColumn(column, ds[:n], text(ds.attrs["units"]), description))
    return StoredGroup(group_path, group_path.rsplit("/", 1)[-1], time_ds[:n].astype(np.float64), tuple(columns),
                       {k: text(v) for k, v in group.attrs.items()})
