"""Part of a run for an export: some channels (`--channels`), a time range (`--start`, `--stop`), one raster
(`--raster`). Every group keeps its own time base unless a raster is asked for; then each is put on the raster by
the import's grid rules (benchlab.importing.grid: enums, states and counters held, the rest interpolated, no gap
bridged). /events keeps its rows (points in time, not samples) within the range."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchlab.errors import InputError
from benchlab.export.content import Channel, ChannelGroup, RunContent
from benchlab.importing.grid import resample


def _whole(channel: Channel) -> bool:
    """Whether a channel is held on a raster: an enum, a state or a counter (unit 1, whole numbers)."""
    values = channel.values[np.isfinite(channel.values)] if channel.values.dtype.kind == "f" else channel.values
    return bool(channel.texts) or channel.values.dtype.kind in "iub" or (
        channel.unit == "1" and bool(np.all(values == np.round(values))))


def _on_raster(group: ChannelGroup, raster: np.ndarray) -> ChannelGroup:
    """The group's channels at the raster's times by their rule."""
    channels = tuple(replace(c, values=resample(group.time, c.values, raster, "hold" if _whole(c) else
                                                "interpolate")) for c in group.channels)
    return replace(group, time=raster, channels=channels, comment=f"{group.comment}; on a raster of "
                                                                  f"{raster[1] - raster[0] if len(raster) > 1 else 0:g} s")


def select(content: RunContent, channels: list[str] | None = None, start: float | None = None,
           stop: float | None = None, raster: float | None = None) -> RunContent:
    """`content` with only the named channels (export names; all if None), the rows from `start` to `stop` (s,
    run time) and, with `raster` (s), every group but /events on one raster from `start` (or the run's first
    time stamp) on; InputError naming an unknown channel or an empty range."""
    known = {c.name for g in content.groups for c in g.channels}
    unknown = [name for name in channels or () if name not in known]
    if unknown:
        raise InputError(content.source, "--channels", f"channels of the run ({', '.join(sorted(known))}), got "
                                                       f"{', '.join(unknown)}")
    low = -np.inf if start is None else start
    high = np.inf if stop is None else stop
    if low > high:
        raise InputError(content.source, "--start", f"a time before --stop ({high:g} s), got {low:g} s")
    everything = np.concatenate([g.time for g in content.groups if len(g.time)] or [np.zeros(0)])
    first = max(low, float(everything.min())) if everything.size else 0.0
    last = min(high, float(everything.max())) if everything.size else 0.0
    grid = None if raster is None else first + np.arange(int(np.floor((last - first) / raster + 1e-9)) + 1) * raster
    groups = []
    for index, group in enumerate(content.groups):
        picked = tuple(c for c in group.channels if channels is None or c.name in channels)
        if not picked and index:  # /aligned stays (CSV and Parquet write it), emptied if none of it is asked for
            continue
        rows = (group.time >= low) & (group.time <= high)
        group = replace(group, time=group.time[rows], channels=tuple(replace(c, values=c.values[rows]) for c in picked))
        groups.append(group if grid is None or group.path == "/events" else _on_raster(group, grid))
    if not len(groups[0].time):
        raise InputError(content.source, "--start", f"a range holding samples of the run ({first:g} s to "
                                                    f"{last:g} s)")
    dt = content.dt if raster is None else raster
    return replace(content, groups=tuple(groups), dt=dt)
