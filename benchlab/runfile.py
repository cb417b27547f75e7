"""Run files (contract section 1): HDF5, schema benchlab-run/1, channels on one grid in /aligned."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from benchlab.errors import InputError

SCHEMA = "benchlab-run/1"
STATUSES = ("running", "complete", "aborted")
#: Every channel the contract names, with its unit; the first ten are required.
ALIGNED_UNITS: dict[str, str] = {
    "time": "s", "engine_speed": "rpm", "clutch_speed": "rpm", "clutch_torque": "N*m", "clutch_state": "1",
    "friction_power": "W", "T_flywheel": "degC", "T_air": "degC", "T_housing": "degC", "T_ambient": "degC",
    "T_engine": "degC", "load_torque": "N*m", "T_flywheel_1": "degC", "T_flywheel_2": "degC",
}
REQUIRED = tuple(list(ALIGNED_UNITS)[:10])
#: What each contract channel is (contract section 1): the comment an export gives the channel.
ALIGNED_MEANING: dict[str, str] = {
    "time": "time since run start, uniform step dt",
    "engine_speed": "ω_e, engine-side (drive motor) speed",
    "clutch_speed": "ω_c, transmission input shaft speed; slip Δω = ω_e − ω_c",
    "clutch_torque": "T_c, torque transmitted by the clutch",
    "clutch_state": "S: 1 clamped (engaged or slipping), 0 open",
    "friction_power": "P = T_c · Δω, Δω in rad/s (eq. 4); 0 when not slipping",
    "T_flywheel": "ϑ_F, mean of the flywheel sensors", "T_air": "ϑ_A, clutch-chamber air",
    "T_housing": "ϑ_T, transmission housing", "T_ambient": "ϑ_amb, ambient", "T_engine": "ϑ_eng, engine",
    "load_torque": "load machine torque", "T_flywheel_1": "flywheel sensor 1", "T_flywheel_2": "flywheel sensor 2",
}
TIME_TOLERANCE = 1e-6  # relative to dt
#: Values a dry-clutch bench can measure, per unit: anything beyond (1e300, inf) is a corrupt number, not a
#: measurement. Channels in other units are only checked for infinities.
MEASURABLE_RANGE: dict[str, tuple[float, float]] = {
    "rpm": (-1e5, 1e5), "N*m": (-1e5, 1e5), "W": (-1e8, 1e8), "degC": (-273.15, 1e4)}
#: How far clutch_state (1 clamped, 0 open) may read from 0 or 1: measurement noise, not a third state.
CLUTCH_STATE_NOISE = 0.05


def _text(value: object) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _open(path: Path) -> h5py.File:
    if not path.exists():
        raise InputError(path, "file", "an existing run file (not found)")
    try:
        return h5py.File(path, "r")
    except OSError:
        raise InputError(path, "file", "an HDF5 run file (cannot be opened as HDF5)") from None


def load_attrs(path: "str | os.PathLike[str]") -> dict[str, str]:
    """Every root attribute of the run file as text (JSON-valued ones such as `sim_truth` stay JSON text)."""
    with _open(Path(path)) as f:
        return {k: _text(v) for k, v in f.attrs.items()}


def load_events(path: "str | os.PathLike[str]") -> list[tuple[float, int, str, str]]:
    """The run's /events as (time s, cycle, kind, detail), up to the progress record of a file still running."""
    path = Path(path)
    with _open(path) as f:
        if "events" not in f:
            raise InputError(path, "/events", "an events table (a run written by benchlab run)")
        g = f["events"]
        n = len(g["time"])
        if "acquire/progress" in f:
            prog = dict(zip(json.loads(f["acquire/progress"].attrs["fields"]), f["acquire/progress"][()]))
            n = min(n, int(prog.get("event_rows", n)))
        return [(float(t), int(c), _text(k), _text(d)) for t, c, k, d in
                zip(g["time"][:n], g["cycle"][:n], g["kind"][:n], g["detail"][:n])]


def load_run(path: "str | os.PathLike[str]", measured: Sequence[str] = (),
             required: Sequence[str] = REQUIRED) -> pd.DataFrame:
    """The /aligned channels as a DataFrame; attrs hold dt, units, source and the root attributes.

    `measured`: channels that must hold at least one measured (not NaN) sample, e.g. the temperatures a model
    is fitted to and started from; a file where one of them is NaN throughout is bad input for that use.
    `required`: channels the file must hold (default the contract's section 1 list; a model file's run needs
    `time` and the channels the model names, contract section 6).
    """
    path = Path(path)
    with _open(path) as f:
        attrs = {k: _text(v) for k, v in f.attrs.items() if k in ("schema", "status", "protocol")}
        if not attrs.get("schema", "").startswith(SCHEMA):
            raise InputError(path, "schema", f"root attribute {SCHEMA!r}, got {attrs.get('schema')!r}")
        if "aligned" not in f or not isinstance(f["aligned"], h5py.Group):
            raise InputError(path, "/aligned", "a group of channels on one time grid")
        group = f["aligned"]
        dt = group.attrs.get("dt")
        if not _is_number(dt) or not np.isfinite(dt) or float(dt) <= 0:
            shown = _text(dt) if isinstance(dt, bytes) else dt
            raise InputError(path, "/aligned.dt", f"a positive time step in seconds (a number), got {shown!r}")
        columns, units = _read_channels(path, group, ("time", *required))
        time_dtype = group["time"].dtype
    frame = pd.DataFrame(columns)
    _check_time(path, frame["time"].to_numpy(), float(dt), time_dtype)
    for name in measured:
        if np.isnan(frame[name].to_numpy()).all():
            raise InputError(path, f"/aligned/{name}", f"at least one measured sample (all {len(frame)} are NaN)")
    frame.attrs.update(attrs, dt=float(dt), units=units, source=str(path))
    return frame


def _read_channels(path: Path, group: h5py.Group,
                   required: Sequence[str]) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    for name in dict.fromkeys(required):
        if name not in group:
            unit = f" in {ALIGNED_UNITS[name]}" if name in ALIGNED_UNITS else " with its unit"
            raise InputError(path, f"/aligned/{name}", f"a required channel{unit} (missing)")
    length = None
    for name, ds in group.items():
        if not isinstance(ds, h5py.Dataset) or ds.ndim != 1 or not np.issubdtype(ds.dtype, np.number):
            raise InputError(path, f"/aligned/{name}", "a 1-D numeric dataset")
        if "units" not in ds.attrs:
            raise InputError(path, f"/aligned/{name}.units", f"a units attribute ({ALIGNED_UNITS.get(name, 'any')})")
        unit = _text(ds.attrs["units"])
        if name in ALIGNED_UNITS and unit != ALIGNED_UNITS[name]:
            raise InputError(path, f"/aligned/{name}.units", f"{ALIGNED_UNITS[name]!r}, got {unit!r}")
        if length is not None and ds.shape[0] != length:
            raise InputError(path, f"/aligned/{name}", f"length {length} like /aligned/time, got {ds.shape[0]}")
        length = ds.shape[0]
        columns[name] = ds[()].astype(np.float64)
        units[name] = unit
        if name != "time":
            problem = unmeasurable_sample(name, unit, columns[name])
            if problem is not None:
                raise InputError(path, f"/aligned/{name}", f"{problem[1]}, got {problem[2]!r} at sample {problem[0]}")
    ordered = {k: columns[k] for k in ALIGNED_UNITS if k in columns}
    ordered.update({k: v for k, v in columns.items() if k not in ordered})
    return ordered, units


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def unmeasurable_sample(name: str, unit: str, values: np.ndarray) -> tuple[int, str, float] | None:
    """The first sample that is neither NaN (not measured) nor a value the bench can measure in its unit
    (clutch_state: 0 or 1), as (index, what was expected, value); None when every sample is fine."""
    if name == "clutch_state":
        near = np.minimum(np.abs(values), np.abs(values - 1.0)) <= CLUTCH_STATE_NOISE
        expected = f"0 (open) or 1 (clamped) within ±{CLUTCH_STATE_NOISE:g}, or NaN"
    elif unit in MEASURABLE_RANGE:
        low, high = MEASURABLE_RANGE[unit]
        near = (values >= low) & (values <= high)
        expected = f"values in [{low:g}, {high:g}] {unit} or NaN (not measured)"
    else:
        near = np.isfinite(values)
        expected = "finite values or NaN (not measured)"
    bad = np.flatnonzero(~near & ~np.isnan(values))
    return (int(bad[0]), expected, float(values[bad[0]])) if bad.size else None


def time_step_tolerance(time: np.ndarray, dt: float, stored: np.dtype) -> float:
    """How far a step may differ from dt: a millionth of dt plus the rounding of the stored type."""
    eps = np.finfo(stored).eps if np.issubdtype(stored, np.floating) else 0.0
    return TIME_TOLERANCE * dt + 4 * eps * float(np.max(np.abs(time)))


def _check_time(path: Path, time: np.ndarray, dt: float, stored: np.dtype) -> None:
    if len(time) < 2:
        raise InputError(path, "/aligned/time", "at least two samples")
    step_error = np.abs(np.diff(time) - dt)
    tolerance = time_step_tolerance(time, dt, stored) if np.all(np.isfinite(time)) else 0.0
    if not np.all(np.isfinite(time)) or np.max(step_error) > tolerance:
        bad = int(np.argmax(~np.isfinite(np.diff(time)) | (step_error > tolerance)))
        raise InputError(path, "/aligned/time", f"a uniform grid with step dt={dt} s (breaks at sample {bad + 1})")


def write_run(path: "str | os.PathLike[str]", frame: pd.DataFrame, dt: float, protocol: str,
              status: str = "complete", units: Mapping[str, str] | None = None) -> None:
    """Write a complete run file: root attributes and every column of `frame` into /aligned."""
    units = {**ALIGNED_UNITS, **dict(units or {})}
    missing = [c for c in frame.columns if c not in units]
    if missing:
        raise ValueError(f"no unit known for channels {missing}")
    with h5py.File(path, "w") as f:
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
    if Path(path).resolve() == Path(run).resolve():
        raise InputError(path, "--out", "a file other than the run file it simulates")
    with h5py.File(run, "r") as src, h5py.File(path, "w") as f:
        f.attrs.update(src.attrs)
        f.attrs.update(attrs)
        src.copy(src["aligned"], f, "aligned")
        _write_group(f, "simulated", src["aligned/time"][()].astype(np.float64),
                     {name: (simulated[name].to_numpy(np.float64), "degC") for name in simulated.columns})


def write_results(path: "str | os.PathLike[str]", group_name: str, time: np.ndarray,
                  columns: Mapping[str, tuple[np.ndarray, str]], attrs: Mapping[str, str]) -> None:
    """Write a results file: root attributes and one group of `time` (s) plus channels, each with its unit."""
    with h5py.File(path, "w") as f:
        f.attrs.update(attrs)
        _write_group(f, group_name, time, columns)


def _write_group(f: h5py.File, group_name: str, time: np.ndarray, columns: Mapping[str, tuple[np.ndarray, str]]) -> None:
    """One group of results: `time` (s) and each channel as float64 with its unit."""
    group = f.create_group(group_name)
    group.create_dataset("time", data=time).attrs["units"] = "s"
    for name, (values, unit) in columns.items():
        group.create_dataset(name, data=np.asarray(values, dtype=np.float64)).attrs["units"] = unit


def load_truth(path: "str | os.PathLike[str]") -> pd.DataFrame | None:
    """The simulated bench's /truth: the plant's true temperatures (degC) on the /aligned grid, named like
    /simulated (T_pressure_plate, ...); None for a run without it (hardware, imported, killed before closing)."""
    path = Path(path)
    with _open(path) as f:
        if "truth" not in f:
            return None
        frame = pd.DataFrame({name: ds[()].astype(np.float64) for name, ds in f["truth"].items()})
    frame.attrs["source"] = str(path)
    return frame
