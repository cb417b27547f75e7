"""What an export carries: a run file's channel groups, each on its own time base, with units and comments.

/aligned (checked by `load_run`), every /raw/<stream>, /events and, in a file written by `benchlab simulate`,
/simulated. Channel names are unique across the export: /aligned keeps the contract's names, the other groups'
channels are `<group>.<column>` (`can_drive.speed`, `events.kind`), each group's time channel `<group>.time`.
A file still being written (status `running`, or left so by a crash) is cut at its progress record: what lies
beyond it is allocated space, not data. Rows go in time order (a stable sort where a stream's stamps step
back); a row whose time stamp is not a number is skipped and counted.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchlab.errors import InputError
from benchlab.export.enums import BusSource, can_sources
from benchlab.runfile import StoredGroup, load_attrs, load_run, load_streams
from benchlab.runfile.schema import aligned_description


@dataclass(frozen=True)
class Channel:
    """One channel: its export name (unique in the export), values, unit, comment and, for a channel from a bus,
    where it comes from (message, node; for an enum the text of each value: the DBC's value table)."""

    name: str
    values: np.ndarray
    unit: str
    comment: str
    bus: BusSource | None = None

    @property
    def texts(self) -> dict[int, str] | None:
        return self.bus.texts if self.bus else None


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


def read_content(path: "str | os.PathLike[str]") -> RunContent:
    """Read a run file for export; a file that is not a run file (contract section 1) is an InputError."""
    path = Path(path)
    run = load_run(path)
    attrs = load_attrs(path)
    stored = load_streams(path)
    sources = stored.layout.get("aligned", {})
    rows = int(stored.progress.get("aligned_rows", len(run)))
    channels = tuple(
        Channel(name, run[name].to_numpy()[:rows], run.attrs["units"][name],
                _aligned_comment(name, sources.get(name), stored.descriptions.get(name)))
        for name in run.columns if name != "time")
    groups = [ChannelGroup("/aligned", "time", run["time"].to_numpy()[:rows], channels,
                           f"uniform grid, dt = {run.attrs['dt']:g} s; NaN = not measured")]
    skipped = 0
    buses = can_sources(attrs) if any(g.name.startswith("can_") for g in stored.groups) else {}
    for group in stored.groups:
        channel_group, dropped = _in_time_order(group, buses)
        skipped += dropped
        if channel_group.channels:
            groups.append(channel_group)
    _check_unique(path, groups)
    return RunContent(path, attrs, float(run.attrs["dt"]), tuple(groups), skipped)


def _aligned_comment(name: str, source: dict | None, description: str | None) -> str:
    """The stored description; for a file written before /aligned carried one, made as the writer makes it."""
    return description if description is not None else aligned_description(name, source)


def _in_time_order(group: StoredGroup, buses: dict[str, BusSource]) -> tuple[ChannelGroup, int]:
    """A stored group as exported: finite time stamps only, in time order, a bus's channels with their source
    (`buses`, or the group's `bus`/`message`/`node` attributes: an imported CAN log's); (group, rows skipped)."""
    time = group.time
    keep = np.isfinite(time)
    if keep.all() and np.all(time[1:] >= time[:-1]):  # as the writer stores them: no copy, no sort
        order: "slice | np.ndarray" = slice(None)
    else:
        order = np.flatnonzero(keep)
        order = order[np.argsort(time[order], kind="stable")]
    attrs_bus = (BusSource(group.attrs["bus"], group.attrs.get("message", ""), group.attrs.get("node", ""))
                 if "bus" in group.attrs else None)
    channels = tuple(Channel(f"{group.name}.{c.name}", c.values[order], c.unit,
                             c.description or f"{group.path}/{c.name} as stored",
                             buses.get(f"{group.name}.{c.name}", attrs_bus))
                     for c in group.columns)
    attrs = ", ".join(f"{k} = {v}" for k, v in group.attrs.items())
    comment = f"{group.path}: own time stamps" + (f"; {attrs}" if attrs else "")
    return ChannelGroup(group.path, f"{group.name}.time", time[order], channels, comment), int(len(time) - keep.sum())


def _check_unique(path: Path, groups: list[ChannelGroup]) -> None:
    seen: set[str] = set()
    for group in groups:
        for name in (group.master, *(c.name for c in group.channels)):
            if name in seen:
                raise InputError(path, f"{group.path}: {name}", "channel names unique across the export")
            seen.add(name)
