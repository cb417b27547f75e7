"""Writing whole run files in one go: `benchlab import` (write_run: /aligned, descriptions, /raw), and `benchlab
simulate` and `benchlab observe` (write_beside_run: the run's root attributes and /aligned plus their own group,
so every command that reads a run reads their output). Each is built beside its destination and renamed into
place when whole (benchlab.outputs.replacing). The file a run writes as it goes is the acquisition writer's
(benchlab/acquire/writer.py)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import h5py
import numpy as np
import pandas as pd

from benchlab.outputs import replacing
from benchlab.runfile.compressed import compressed_dataset
from benchlab.runfile.schema import ALIGNED_UNITS, SCHEMA, aligned_description

#: A channel of a group besides /aligned: values, unit and a description ("" for none).
Column = tuple[np.ndarray, str, str]


@dataclass(frozen=True)
class RawStream:
    """One source's channels at their own time stamps, as the file held them: /raw/<name> (`time` in s)."""

    name: str
    time: np.ndarray
    columns: Mapping[str, Column]
    attrs: Mapping[str, object] = field(default_factory=dict)


def write_run(path: "str | os.PathLike[str]", frame: pd.DataFrame, dt: float, protocol: str,
              status: str = "complete", units: Mapping[str, str] | None = None,
              attrs: Mapping[str, str] | None = None, sources: Mapping[str, dict] | None = None,
              raw: tuple[RawStream, ...] = ()) -> None:
    """Write a complete run file: root attributes (`attrs` beside the contract's), every column of `frame` into
    /aligned with its description (where `sources` says it came from: aligned_description), and `raw` streams."""
    units = {**ALIGNED_UNITS, **dict(units or {})}
    missing = [c for c in frame.columns if c not in units]
    if missing:
        raise ValueError(f"no unit known for channels {missing}")
    sources = dict(sources or {})
    with replacing(path, run_file=True) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(dict(attrs or {}))
        f.attrs.update(schema=SCHEMA, status=status, protocol=protocol)
        group = f.create_group("aligned")
        group.attrs["dt"] = float(dt)
        for name in frame.columns:
            ds = _dataset(group, name, frame[name].to_numpy(np.float64))
            ds.attrs["units"] = units[name]
            ds.attrs["description"] = aligned_description(name, sources.get(name))
        if raw:
            parent = f.create_group("raw")
            for stream in raw:
                _write_group(parent, stream.name, stream.time, stream.columns).attrs.update(dict(stream.attrs))


def write_beside_run(path: "str | os.PathLike[str]", run: "str | os.PathLike[str]", group_name: str,
                     time: np.ndarray, columns: Mapping[str, Column], attrs: Mapping[str, object]) -> None:
    """Write a run file in its own right: the run's root attributes and /aligned (copied as stored) plus the group
    `group_name` at `time` (the run's grid, s) (/simulated, /estimated: each column with its unit and description) and
    `attrs` saying where it came from (source run, parameters, model, ...)."""
    with replacing(path, run_file=True) as tmp, h5py.File(run, "r") as src, h5py.File(tmp, "w") as f:
        f.attrs.update(src.attrs)
        f.attrs.update(dict(attrs))
        src.copy(src["aligned"], f, "aligned")
        _write_group(f, group_name, time, columns)


def _dataset(group: h5py.Group, name: str, values: np.ndarray) -> h5py.Dataset:
    """A compressed 1-D dataset (gzip with shuffle: about a quarter of the raw size for bench channels)."""
    return compressed_dataset(group, name, values)


def _write_group(parent: h5py.Group, name: str, time: np.ndarray, columns: Mapping[str, Column]) -> h5py.Group:
    """One time-stamped group: `time` (s) and each channel with its unit and, where it has one, its description."""
    group = parent.create_group(name)
    _dataset(group, "time", np.asarray(time, dtype=np.float64)).attrs["units"] = "s"
    for column, (values, unit, description) in columns.items():
        values = np.asarray(values)
        ds = _dataset(group, column, values if values.dtype.kind == "S" else values.astype(np.float64))
        ds.attrs["units"] = unit
        if description:
            ds.attrs["description"] = description
    return group
