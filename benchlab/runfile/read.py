"""Reading a run file: root attributes, /aligned (checked as the contract says), /events, the progress record,
/schedule, /truth, and what `--resume` needs. Every reader opens the file through `open_run` (one InputError
for a missing or non-HDF5 file)."""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import h5py
import numpy as np

from benchlab.bounds import MAX_CYCLES, MAX_GRID_STEP_S, MAX_RESUMES, MAX_RUN_DURATION_S
from benchlab.errors import InputError
from benchlab.runfile.schema import (ALIGNED_UNITS, EVENT_FIELDS, REQUIRED, SCHEMA, time_stamp_problem,
                                     time_step_tolerance, unmeasurable_sample)
from benchlab.units import same as same_unit
from protocols.schedule import Step, steps_from_rows

if TYPE_CHECKING:  # pandas loads where a frame is built: the run and watch paths read no frame
    import pandas as pd


def text(value: object) -> str:
    """An HDF5 attribute or fixed-length string as text (bytes decoded as UTF-8)."""
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


#: How HDF5 (through h5py) starts the message of a failed read: a damaged or truncated file's object or data.
HDF5_READ_FAILED = re.compile(r"^'?(Unable to|Can't|Could not|Cannot)\b")


def hdf5_damage(exc: BaseException) -> bool:
    """Whether `exc` is HDF5 failing to read what the file claims to hold (a corrupt or truncated file), not a
    mistake of ours: h5py raises OSError, KeyError, RuntimeError or ValueError with HDF5's text."""
    return isinstance(exc, (OSError, KeyError, RuntimeError, ValueError)) and bool(HDF5_READ_FAILED.match(str(exc)))


class RunFile(h5py.File):
    """A run file opened by open_run: HDF5 failing to read part of it inside its `with` block is InputError naming
    the file as damaged (exit 2), not a Python error."""

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        super().__exit__(exc_type, exc, tb)
        if exc is not None and hdf5_damage(exc):
            detail = " ".join(str(exc).strip("'").split())
            raise InputError(self.source, "file", f"an intact HDF5 run file (corrupt or truncated: {detail})") from None


def open_run(path: "str | os.PathLike[str]", mode: str = "r") -> RunFile:
    """The run file opened with h5py; InputError if it does not exist, is not a regular file, is not HDF5, or (in
    its `with` block) is damaged."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file", "an existing run file (not found)")
    if not path.is_file():
        raise InputError(path, "file", "a run file (a regular file, not a directory or a device)")
    try:
        f = RunFile(path, mode)
    except OSError:
        raise InputError(path, "file", "an HDF5 run file (cannot be opened as HDF5)") from None
    f.source = path
    return f


def stored_schema(path: "str | os.PathLike[str]") -> str | None:
    """The root attribute `schema` of an HDF5 file if it is the run files' (SCHEMA); None for any other file,
    HDF5 or not (benchlab.outputs: a run file is never written over by mistake)."""
    try:
        with h5py.File(path, "r") as f:
            return SCHEMA if text(f.attrs.get("schema", "")) == SCHEMA else None
    except OSError:
        return None


def load_attrs(path: "str | os.PathLike[str]") -> dict[str, str]:
    """Every root attribute of the run file as text (JSON-valued ones such as `sim_truth` stay JSON text)."""
    with open_run(path) as f:
        return {k: text(v) for k, v in f.attrs.items()}


def read_progress(f: h5py.File) -> dict[str, float]:
    """The progress record of a run file written by RunWriter: field -> value."""
    ds = f["acquire/progress"]
    return dict(zip(json.loads(ds.attrs["fields"]), (float(v) for v in ds[()])))


def load_progress(path: "str | os.PathLike[str]") -> dict[str, float]:
    """The run's progress record (field -> value); empty for a file without one (imported: every row valid)."""
    with open_run(path) as f:
        return read_progress(f) if "acquire/progress" in f else {}


class Event(NamedTuple):
    """One row of /events (docs/runfile.md): `step` is the row of /schedule it belongs to, -1 for none; `reason`
    what a program matches (the interlock's name, why a step ended), "" for none."""

    time: float
    cycle: int
    kind: str
    detail: str
    step: int
    reason: str


def legacy_reason(kind: str, detail: str) -> str:
    """An event's `reason` in a file written before /events had the column, from the runner's detail text of
    then (`NAME: what it saw (action)`, `REASON; point`, `PHASE: REASON`): the one place that text is parsed."""
    if kind == "interlock":
        return detail.split(":", 1)[0]
    if kind == "cooldown_end":
        return detail.split(";", 1)[0].strip()
    if kind == "step_end":
        return detail.partition(": ")[2].strip()
    return ""


def complete_events(stored: Mapping[str, np.ndarray], rows: int) -> dict[str, np.ndarray]:
    """Every column of EVENT_FIELDS for `rows` events, as stored, from the columns a file holds (`stored`):
    one newer than the file reads as its writer would have written it: `step` -1 (not known), `reason` from
    the detail text (legacy_reason)."""
    columns = {name: stored[name][:rows] if name in stored else np.full(rows, fill, dtype=dtype)
               for name, (dtype, _, fill) in EVENT_FIELDS.items()}
    if "reason" not in stored:
        reasons = [legacy_reason(text(k), text(d)).encode("utf-8") for k, d in zip(columns["kind"], columns["detail"])]
        columns["reason"] = np.array(reasons, dtype=EVENT_FIELDS["reason"][0])
    return columns


def load_events(path: "str | os.PathLike[str]") -> list[Event]:
    """The run's /events, up to the progress record of a file still running; a file written before a column
    existed reads as complete_events fills it."""
    path = Path(path)
    with open_run(path) as f:
        if "events" not in f:
            raise InputError(path, "/events", "an events table (a run written by benchlab run)")
        g = f["events"]
        n = len(g["time"])
        if "acquire/progress" in f:
            n = min(n, int(read_progress(f).get("event_rows", n)))
        columns = complete_events({c: g[c][:n] for c in EVENT_FIELDS if c in g}, n)
        return [Event(float(t), int(c), text(k), text(d), int(s), text(r))
                for t, c, k, d, s, r in zip(*columns.values())]


def event_steps(events: Sequence[Event], steps: Sequence[Step]) -> list[int]:
    """The row of /schedule (`steps`) each event belongs to: its `step`, or, for a `step_start` of a file written
    before events carried it (-1), its place: the k-th step_start after its cycle's latest `cycle_start` starts
    the cycle's k-th step (the runner starts every cycle at its first step: a resume the next cycle, an interlock
    skips the rest of the cycle). -1 where there is none."""
    rows_of = {cycle: [i for i, s in enumerate(steps) if s.cycle == cycle] for cycle in {s.cycle for s in steps}}
    started: dict[int, int] = {}  # cycle -> step_starts since its latest cycle_start
    out = []
    for event in events:
        step = event.step
        if event.kind == "cycle_start":
            started[event.cycle] = 0
        elif event.kind == "step_start":
            k = started[event.cycle] = started.get(event.cycle, 0) + 1
            rows = rows_of.get(event.cycle, [])
            if step < 0 and k <= len(rows):
                step = rows[k - 1]
        out.append(step)
    return out


def read_schedule(f: h5py.File, path: Path) -> tuple[Step, ...]:
    """The schedule stored in /schedule, read back by the one schedule parser (types and field names checked)."""
    group = f.get("schedule")
    return _parse_schedule(group.attrs.get("steps_json") if isinstance(group, h5py.Group) else None, path)


def _parse_schedule(stored: object, path: Path) -> tuple[Step, ...]:
    """/schedule's `steps_json` as Steps: JSON, then the one schedule parser (protocols.schedule)."""
    try:
        rows = json.loads(stored) if isinstance(stored, (str, bytes)) else None
    except ValueError:
        rows = None
    if rows is None:
        raise InputError(path, "/schedule steps_json", "the schedule as a JSON list of steps (missing or not JSON)")
    return steps_from_rows(rows, str(path))


def load_schedule(path: "str | os.PathLike[str]") -> tuple[Step, ...]:
    """The run's planned schedule (/schedule); InputError naming the step and field of a malformed one."""
    path = Path(path)
    with open_run(path) as f:
        return read_schedule(f, path)


def grid_step(path: Path, group: h5py.Group) -> float:
    """/aligned's `dt` as a float; InputError unless it is a positive finite number."""
    dt = group.attrs.get("dt")
    number = isinstance(dt, (int, float, np.integer, np.floating)) and not isinstance(dt, (bool, np.bool_))
    if not number or not np.isfinite(dt) or float(dt) <= 0:
        shown = text(dt) if isinstance(dt, bytes) else dt
        raise InputError(path, "/aligned.dt", f"a positive time step in seconds (a number), got {shown!r}")
    return float(dt)


def load_run(path: "str | os.PathLike[str]", measured: Sequence[str] = (),
             required: Sequence[str] = REQUIRED, only: Sequence[str] | None = None) -> pd.DataFrame:
    """The /aligned channels as a DataFrame; attrs hold dt, units, source and the root attributes.

    `measured`: channels that must hold at least one measured (not NaN) sample, e.g. the temperatures a model
    is fitted to and started from; a file where one of them is NaN throughout is bad input for that use.
    `required`: channels the file must hold (default the contract's section 1 list; a model file's run needs
    `time` and the channels the model names, contract section 6). `only`: read (and check) only `time`, the
    required channels and these where the file holds them, for a command that uses no other (a simulation).
    """
    import pandas as pd

    path = Path(path)
    with open_run(path) as f:
        attrs = {k: text(v) for k, v in f.attrs.items() if k in ("schema", "status", "protocol", "bench")}
        if not attrs.get("schema", "").startswith(SCHEMA):
            raise InputError(path, "schema", f"root attribute {SCHEMA!r}, got {attrs.get('schema')!r}")
        if "aligned" not in f or not isinstance(f["aligned"], h5py.Group):
            raise InputError(path, "/aligned", "a group of channels on one time grid")
        group = f["aligned"]
        dt = grid_step(path, group)
        wanted = None if only is None else {"time", *required, *only}
        columns, units = _read_channels(path, group, ("time", *required), wanted)
        time_dtype = group["time"].dtype
    frame = pd.DataFrame(columns)
    _check_time(path, frame["time"].to_numpy(), dt, time_dtype)
    for name in measured:
        if np.isnan(frame[name].to_numpy()).all():
            raise InputError(path, f"/aligned/{name}", f"at least one measured sample (all {len(frame)} are NaN)")
    frame.attrs.update(attrs, dt=dt, units=units, source=str(path))
    return frame


def _read_channels(path: Path, group: h5py.Group, required: Sequence[str],
                   wanted: set[str] | None = None) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    for name in dict.fromkeys(required):
        if name not in group:
            unit = f" in {ALIGNED_UNITS[name]}" if name in ALIGNED_UNITS else " with its unit"
            raise InputError(path, f"/aligned/{name}", f"a required channel{unit} (missing)")
    length = None
    for name, ds in group.items():
        if wanted is not None and name not in wanted:
            continue
        if not isinstance(ds, h5py.Dataset) or ds.ndim != 1 or not np.issubdtype(ds.dtype, np.number):
            raise InputError(path, f"/aligned/{name}", "a 1-D numeric dataset")
        if "units" not in ds.attrs:
            raise InputError(path, f"/aligned/{name}.units", f"a units attribute ({ALIGNED_UNITS.get(name, 'any')})")
        unit = text(ds.attrs["units"])
        if name in ALIGNED_UNITS:  # another tool may spell the contract's unit its own way (°C, Nm, 1/min)
            if not same_unit(unit, ALIGNED_UNITS[name]):
                raise InputError(path, f"/aligned/{name}.units", f"{ALIGNED_UNITS[name]!r}, got {unit!r}")
            unit = ALIGNED_UNITS[name]
        if length is not None and ds.shape[0] != length:
            raise InputError(path, f"/aligned/{name}", f"length {length} like /aligned/time, got {ds.shape[0]}")
        length = ds.shape[0]
        columns[name] = ds[()].astype(np.float64, copy=False)  # read afresh: no second copy of a float64 one
        units[name] = unit
        if name != "time":
            problem = unmeasurable_sample(name, unit, columns[name])
            if problem is not None:
                raise InputError(path, f"/aligned/{name}", f"{problem[1]}, got {problem[2]!r} at sample {problem[0]}")
    ordered = {k: columns[k] for k in ALIGNED_UNITS if k in columns}
    ordered.update({k: v for k, v in columns.items() if k not in ordered})
    return ordered, units


def _check_time(path: Path, time: np.ndarray, dt: float, stored: np.dtype) -> None:
    if len(time) < 2:
        raise InputError(path, "/aligned/time", "at least two samples")
    if (problem := time_stamp_problem(time)) and np.all(np.isfinite(time)):
        raise InputError(path, "/aligned/time", problem)
    step_error = np.abs(np.diff(time) - dt)
    tolerance = time_step_tolerance(time, dt, stored) if np.all(np.isfinite(time)) else 0.0
    if not np.all(np.isfinite(time)) or np.max(step_error) > tolerance:
        bad = int(np.argmax(~np.isfinite(np.diff(time)) | (step_error > tolerance)))
        raise InputError(path, "/aligned/time", f"a uniform grid with step dt={dt} s (breaks at sample {bad + 1})")


def load_truth(path: "str | os.PathLike[str]") -> pd.DataFrame | None:
    """The simulated bench's /truth: the plant's true temperatures (degC) on the /aligned grid, named like
    /simulated (T_pressure_plate, ...), up to the progress record in a file still running or killed (NaN where no
    final state had been written); None for a run without it (hardware, imported, killed before this was written
    as the run went)."""
    import pandas as pd

    path = Path(path)
    with open_run(path) as f:
        if "truth" not in f:
            return None
        rows = int(read_progress(f)["aligned_rows"]) if "acquire/progress" in f else None
        frame = pd.DataFrame({name: ds[:rows].astype(np.float64) for name, ds in f["truth"].items()})
    frame.attrs["source"] = str(path)
    return frame


@dataclass(frozen=True)
class StoppedRun:
    """Where a run written by `benchlab run` stopped, as its file says: what `--resume` continues from."""

    path: Path
    attrs: dict[str, str]  # root attributes as text
    progress: dict[str, float]  # the progress record
    dt: float
    last_valid: dict[str, float]  # newest measured value (NaN: none) of each channel asked for, up to the progress
    _schedule: object  # /schedule's steps_json as stored, parsed by `steps()`

    @property
    def rows(self) -> int:
        return int(self.progress["aligned_rows"])

    def steps(self) -> tuple[Step, ...]:
        """The stored schedule, read back by the one schedule parser (InputError naming step and field)."""
        return _parse_schedule(self._schedule, self.path)


def load_stopped_run(path: "str | os.PathLike[str]", channels: Sequence[str]) -> StoppedRun:
    """What a run file says about where its run stopped (see StoppedRun); InputError for a file without a
    progress record or schedule (not written by `benchlab run`)."""
    path = Path(path)
    with open_run(path) as f:
        if "acquire/progress" not in f or "schedule" not in f:
            raise InputError(path, "/acquire/progress", "a run file written by benchlab run (no progress record)")
        progress = read_progress(f)
        dt = grid_step(path, f["aligned"]) if "aligned" in f else 0.0
        rows = _check_stopped(path, f, progress, dt)
        last = {name: _last_valid(f[f"aligned/{name}"][:rows] if f"aligned/{name}" in f else np.empty(0))
                for name in channels}
        return StoppedRun(path, {k: text(v) for k, v in f.attrs.items()}, progress, dt, last,
                          f["schedule"].attrs.get("steps_json"))


def _whole(value: float, low: float, high: float) -> bool:
    return math.isfinite(value) and value == int(value) and low <= value <= high


def _check_stopped(path: Path, f: h5py.File, progress: Mapping[str, float], dt: float) -> int:
    """The rows `--resume` continues after, once every size, step and attribute it reads is checked against
    benchlab.bounds (a tampered file used to allocate petabytes or fail with a Python error): InputError else."""
    if "aligned/time" not in f:
        raise InputError(path, "/aligned/time", "the run's time channel (missing)")
    if dt > MAX_GRID_STEP_S:
        raise InputError(path, "/aligned.dt", f"a time step of at most {MAX_GRID_STEP_S:g} s, got {dt:g}")
    stored = f["aligned/time"].shape[0] if f["aligned/time"].ndim == 1 else 0
    rows = progress.get("aligned_rows", math.nan)
    if not _whole(rows, 0, stored) or rows * dt > MAX_RUN_DURATION_S:
        raise InputError(path, "/acquire/progress aligned_rows", f"a whole number of rows in [0, {stored}] (what "
                                                                 f"/aligned holds), at most {MAX_RUN_DURATION_S:g} s "
                                                                 f"of run, got {rows:g}")
    for field, low, high in (("state/resumes", 0, MAX_RESUMES), ("state/cycle", -1, MAX_CYCLES)):
        value = progress.get(field, math.nan)
        if not (math.isnan(value) or _whole(value, low, high)):
            raise InputError(path, f"/acquire/progress {field}", f"a whole number in [{low}, {high}], got {value:g}")
    seed = text(f.attrs.get("seed", "0"))
    if not (seed.isascii() and seed.isdigit()):
        raise InputError(path, "seed", f"the run's seed, a whole number >= 0, got {seed!r}")
    try:
        options = json.loads(text(f.attrs.get("protocol_options", "{}")))
    except (ValueError, RecursionError):
        options = None
    if not isinstance(options, dict):
        raise InputError(path, "protocol_options", "the protocol's options as a JSON object")
    return int(rows)


def _last_valid(values: np.ndarray) -> float:
    valid = values[np.isfinite(values)]
    return float(valid[-1]) if valid.size else math.nan
