"""What an export carries: a run file's channel groups, each on its own time base, with units and comments.

/aligned (checked by `load_run`), every /raw/<stream>, /events and, in a file written by `benchlab simulate`,
/simulated. Channel names are unique across the export: /aligned keeps the contract's names, the other groups'
channels are `<group>.<column>` (`can_drive.speed`, `events.kind`), each group's time channel `<group>.time`.
A file still being written (status `running`, or left so by a crash) is cut at its progress record: what lies
beyond it is allocated space, not data. Rows go in time order (a stable sort where a stream's stamps step
back); a row whose time stamp is not a number is skipped and counted.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from benchlab.acquire import read_progress
from benchlab.errors import InputError
from benchlab.runfile import ALIGNED_MEANING, load_attrs, load_run


@dataclass(frozen=True)
class Channel:
    """One channel: its export name (unique in the export), values, unit and comment."""

    name: str
    values: np.ndarray
    unit: str
    comment: str


@dataclass(frozen=True)
class ChannelGroup:
    """Channels sharing one time base, as stored under `path` in the run file."""

    path: str
    master: str
    time: np.ndarray
    channels: tuple[Channel, ...]
    comment: str


@dataclass(frozen=True)
class RunContent:
    """Everything an export writes: the run file's root attributes (as text) and its channel groups."""

    source: Path
    attrs: dict[str, str]
    dt: float
    groups: tuple[ChannelGroup, ...]
    skipped_rows: int

    @property
    def aligned(self) -> ChannelGroup:
        return self.groups[0]


def _text(value: object) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def read_content(path: "str | os.PathLike[str]") -> RunContent:
    """Read a run file for export; a file that is not a run file (contract section 1) is an InputError."""
    path = Path(path)
    run = load_run(path)
    attrs = load_attrs(path)
    with h5py.File(path, "r") as f:
        progress = read_progress(f) if "acquire/progress" in f else {}
        layout = f["acquire"].attrs.get("layout", "{}") if isinstance(f.get("acquire"), h5py.Group) else "{}"
        sources = json.loads(_text(layout)).get("aligned", {})
        rows = int(progress.get("aligned_rows", len(run)))
        channels = tuple(
            Channel(name, run[name].to_numpy()[:rows], run.attrs["units"][name],
                    _aligned_comment(name, sources.get(name), f["aligned"][name].attrs))
            for name in run.columns if name != "time")
        groups = [ChannelGroup("/aligned", "time", run["time"].to_numpy()[:rows], channels,
                               f"uniform grid, dt = {run.attrs['dt']:g} s; NaN = not measured")]
        skipped = 0
        for group_path, prefix, limit in _other_groups(f, progress):
            group, dropped = _read_group(path, f[group_path], group_path, prefix, limit)
            skipped += dropped
            if group.channels:
                groups.append(group)
    _check_unique(path, groups)
    return RunContent(path, attrs, float(run.attrs["dt"]), tuple(groups), skipped)


def _aligned_comment(name: str, source: dict | None, attrs: h5py.AttributeManager) -> str:
    parts = [_text(attrs["description"])] if "description" in attrs else []
    parts += [ALIGNED_MEANING[name]] if name in ALIGNED_MEANING else []
    if source:
        scale = f" × {source['scale']:g}" if source.get("scale", 1.0) != 1.0 else ""
        parts.append(f"from {source['stream']}.{source['column']}{scale}, held on the grid")
    return "; ".join(parts)


def _other_groups(f: h5py.File, progress: dict[str, float]) -> list[tuple[str, str, int | None]]:
    """(HDF5 path, name prefix, valid rows or None) of every time-stamped group besides /aligned."""
    out: list[tuple[str, str, int | None]] = []
    if isinstance(f.get("raw"), h5py.Group):
        for stream, group in f["raw"].items():
            if isinstance(group, h5py.Group) and "time" in group:
                rows = progress.get(f"rows/{stream}")
                out.append((f"/raw/{stream}", stream, None if rows is None else int(rows)))
    for name, counter in (("events", "event_rows"), ("simulated", None)):
        if isinstance(f.get(name), h5py.Group) and "time" in f[name]:
            rows = progress.get(counter) if counter else None
            out.append((f"/{name}", name, None if rows is None else int(rows)))
    return out


def _read_group(path: Path, group: h5py.Group, group_path: str, prefix: str,
                limit: int | None) -> tuple[ChannelGroup, int]:
    """One group: valid rows only (progress record), finite time stamps, in time order; (group, rows skipped)."""
    time_ds = group["time"]
    if time_ds.ndim != 1 or not np.issubdtype(time_ds.dtype, np.number):
        raise InputError(path, f"{group_path}/time", "a 1-D numeric dataset of time stamps in s")
    n = time_ds.shape[0] if limit is None else min(limit, time_ds.shape[0])
    time = time_ds[:n].astype(np.float64)
    keep = np.isfinite(time)
    if keep.all() and np.all(time[1:] >= time[:-1]):  # as the writer stores them: no copy, no sort
        order: "slice | np.ndarray" = slice(None)
    else:
        order = np.flatnonzero(keep)
        order = order[np.argsort(time[order], kind="stable")]
    channels = []
    for column, ds in group.items():
        if column == "time" or not isinstance(ds, h5py.Dataset):
            continue
        if ds.ndim != 1 or ds.shape[0] != time_ds.shape[0]:
            raise InputError(path, f"{group_path}/{column}", f"a 1-D dataset as long as {group_path}/time")
        if "units" not in ds.attrs:
            raise InputError(path, f"{group_path}/{column}.units", "a units attribute")
        if not (np.issubdtype(ds.dtype, np.number) or ds.dtype.kind == "S"):
            raise InputError(path, f"{group_path}/{column}", "numbers or byte strings")
        comment = _text(ds.attrs["description"]) if "description" in ds.attrs else ""
        channels.append(Channel(f"{prefix}.{column}", ds[:n][order], _text(ds.attrs["units"]),
                                comment or f"{group_path}/{column} as stored"))
    attrs = ", ".join(f"{k} = {_text(v)}" for k, v in group.attrs.items())
    comment = f"{group_path}: own time stamps" + (f"; {attrs}" if attrs else "")
    return ChannelGroup(group_path, f"{prefix}.time", time[order], tuple(channels), comment), int(n - keep.sum())


def _check_unique(path: Path, groups: list[ChannelGroup]) -> None:
    seen: set[str] = set()
    for group in groups:
        for name in (group.master, *(c.name for c in group.channels)):
            if name in seen:
                raise InputError(path, f"{group.path}: {name}", "channel names unique across the export")
            seen.add(name)
