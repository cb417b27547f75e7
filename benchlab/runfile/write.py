"""Writing whole run files and results files in one go: `benchlab import` (write_run), `benchlab simulate`
(write_simulated) and `benchlab observe` (write_results). Each is built beside its destination and renamed into
place when whole (benchlab.outputs.replacing). The file a run writes as it goes is the acquisition writer's
(benchlab/acquire/writer.py)."""

from __future__ import annotations

import os
from collections.abc import Mapping

import h5py
import numpy as np
import pandas as pd

from benchlab.outputs import replacing
from benchlab.runfile.schema import ALIGNED_UNITS, SCHEMA


def write_run(path: "str | os.PathLike[str]", frame: pd.DataFrame, dt: float, protocol: str,
              status: str = "complete", units: Mapping[str, str] | None = None,
              attrs: Mapping[str, str] | None = None) -> None:
    """Write a complete run file: root attributes (`attrs` beside the contract's) and every column of `frame` into
    /aligned."""
    units = {**ALIGNED_UNITS, **dict(units or {})}
    missing = [c for c in frame.columns if c not in units]
    if missing:
        raise ValueError(f"no unit known for channels {missing}")
    with replacing(path, run_file=True) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(dict(attrs or {}))
        f.attrs.update(schema=SCHEMA, status=status, protocol=protocol)
        group = f.create_group("aligned")
        group.attrs["dt"] = float(dt)
        for name in frame.columns:
            ds = group.create_dataset(name, data=frame[name].to_numpy(np.float64), compression="gzip",
                                      compression_opts=4, shuffle=True)
            ds.attrs["units"] = units[name]


def write_simulated(path: "str | os.PathLike[str]", run: "str | os.PathLike[str]", simulated: pd.DataFrame,
                    attrs: Mapping[str, str]) -> None:
    """Write SIM.h5: a run file in its own right (the run's root attributes and /aligned, copied as stored, so
    every command that reads a run reads it) plus the contract's /simulated group on the run's grid (time, s;
    the model's temperatures, degC) and `attrs` saying where it came from (source run, parameters, model)."""
    with replacing(path, run_file=True) as tmp, h5py.File(run, "r") as src, h5py.File(tmp, "w") as f:
        f.attrs.update(src.attrs)
        f.attrs.update(attrs)
        src.copy(src["aligned"], f, "aligned")
        _write_group(f, "simulated", src["aligned/time"][()].astype(np.float64),
                     {name: (simulated[name].to_numpy(np.float64), "degC") for name in simulated.columns})


def write_results(path: "str | os.PathLike[str]", group_name: str, time: np.ndarray,
                  columns: Mapping[str, tuple[np.ndarray, str]], attrs: Mapping[str, str]) -> None:
    """Write a results file: root attributes and one group of `time` (s) plus channels, each with its unit."""
    with replacing(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(attrs)
        _write_group(f, group_name, time, columns)


def _write_group(f: h5py.File, group_name: str, time: np.ndarray, columns: Mapping[str, tuple[np.ndarray, str]]) -> None:
    """One group of results: `time` (s) and each channel as float64 with its unit."""
    group = f.create_group(group_name)
    group.create_dataset("time", data=time).attrs["units"] = "s"
    for name, (values, unit) in columns.items():
        group.create_dataset(name, data=np.asarray(values, dtype=np.float64)).attrs["units"] = unit
