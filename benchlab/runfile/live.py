"""Reading a run file while `benchlab run` writes it, without ever writing to it, and only what is new
(`benchlab watch`).

While a run acquires, the writer (benchlab/acquire/writer.py, docs/runfile.md "Crash safety") never changes the
file's structure: it overwrites bytes inside datasets allocated when the file was made, then the progress record
`/acquire/progress`, which says how far the data is valid. So a version of the file is opened once: HDF5 (through
a read-only descriptor, no lock) tells where each contiguous dataset's bytes lie, and from then on the progress
record and the new rows are read with `pread` on that descriptor. That bypasses HDF5's caches (which could hold
bytes the writer has overwritten since) and costs what is new, not what the run has grown to. Compressed datasets
(a closed, compacted run) are read through h5py: such a file no longer changes. The writer replaces the file
(`os.replace`) when it grows, resumes and closes; the new version is a new inode at the same path.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from stat import S_ISREG
from typing import Any

import h5py
import numpy as np

from benchlab.errors import InputError
from benchlab.runfile.read import complete_events, grid_step, read_schedule, text
from benchlab.runfile.schema import EVENT_FIELDS, EVENT_REQUIRED, SCHEMA
from protocols.schedule import Step


class _PreadColumn:
    """A contiguous dataset read straight from the file's bytes (what the writer's memory mapping wrote)."""

    def __init__(self, fd: int, offset: int, dtype: np.dtype, length: int) -> None:
        self.fd, self.offset, self.dtype, self.length = fd, offset, dtype, length

    def read(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.length)
        if stop <= start:
            return np.empty(0, self.dtype)
        size = self.dtype.itemsize
        want = (stop - start) * size
        chunks, got = [], 0
        while got < want:
            chunk = os.pread(self.fd, want - got, self.offset + start * size + got)
            if not chunk:
                raise OSError(f"run file ends inside a dataset (offset {self.offset + start * size + got})")
            chunks.append(chunk)
            got += len(chunk)
        return np.frombuffer(b"".join(chunks), dtype=self.dtype)


class _H5Column:
    """A dataset read through h5py (compressed or chunked: the file is closed and compacted, it no longer changes)."""

    def __init__(self, dataset: h5py.Dataset) -> None:
        self.dataset, self.length = dataset, int(dataset.shape[0])

    def read(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.length)
        return self.dataset[start:stop] if stop > start else np.empty(0, self.dataset.dtype)


Column = _PreadColumn | _H5Column


def _column(dataset: h5py.Dataset, fd: int) -> Column:
    contiguous = dataset.chunks is None and not dataset.compression
    offset = dataset.id.get_offset() if contiguous else None
    if offset is None:
        return _H5Column(dataset)
    return _PreadColumn(fd, int(offset), dataset.dtype, int(dataset.shape[0]))


class RunFileVersion:
    """One version (inode) of a run file, open read-only: attributes, schedule and a reader per dataset.

    Raises InputError if the file is not a run file (schema benchlab-run/1 with an /aligned grid).
    """

    def __init__(self, path: "str | os.PathLike[str]") -> None:
        self.path = Path(path)
        try:
            self.fd = os.open(self.path, os.O_RDONLY)
        except FileNotFoundError:
            raise InputError(self.path, "file", "an existing run file (not found)") from None
        except OSError as exc:
            raise InputError(self.path, "file", f"a readable run file ({exc.strerror})") from None
        try:
            stat = os.fstat(self.fd)
            if not S_ISREG(stat.st_mode):
                raise InputError(self.path, "file", "a run file (a regular file, not a directory or a device)")
            self.inode = (stat.st_dev, stat.st_ino)
            self._h5 = self._open_hdf5()
            self._index()
        except BaseException:
            self.close()
            raise

    def _open_hdf5(self) -> h5py.File:
        """HDF5 on the same inode as the descriptor (not the path, which the writer may replace meanwhile)."""
        self._handle = io.FileIO(os.dup(self.fd), "rb")
        try:
            return h5py.File(self._handle, "r")
        except OSError:
            raise InputError(self.path, "file", "an HDF5 run file (cannot be opened as HDF5)") from None

    def _index(self) -> None:
        f = self._h5
        self.attrs = {k: text(v) if isinstance(v, (bytes, str)) else v for k, v in f.attrs.items()}
        schema = str(self.attrs.get("schema", ""))
        if not schema.startswith(SCHEMA):
            raise InputError(self.path, "schema", f"root attribute {SCHEMA!r} of a run file, got {schema or None!r}")
        group = f.get("aligned")
        if not isinstance(group, h5py.Group) or not isinstance(group.get("time"), h5py.Dataset):
            raise InputError(self.path, "/aligned", "a group of channels on one time grid with a 'time' dataset")
        self.dt = grid_step(self.path, group)
        time = group["time"]
        self.capacity = int(time.shape[0]) if time.ndim == 1 else 0
        self.t0 = float(time[0]) if self.capacity else 0.0
        if not np.isfinite(self.t0):
            raise InputError(self.path, "/aligned/time", f"a time grid starting at a number, got {self.t0}")
        self.channels: dict[str, str] = {}  # name -> unit, file order, time excluded
        self.columns: dict[str, Column] = {}
        for name, ds in group.items():
            if (name == "time" or not isinstance(ds, h5py.Dataset) or ds.ndim != 1
                    or ds.shape[0] != self.capacity or not np.issubdtype(ds.dtype, np.number)):
                continue
            self.channels[name] = text(ds.attrs.get("units", ""))
            self.columns[name] = _column(ds, self.fd)
        self.events: dict[str, Column] = {}
        events = f.get("events")
        if isinstance(events, h5py.Group) and all(isinstance(events.get(c), h5py.Dataset) for c in EVENT_REQUIRED):
            self.events = {c: _column(events[c], self.fd) for c in EVENT_FIELDS
                           if isinstance(events.get(c), h5py.Dataset)}
        self.progress_fields: list[str] = []
        self._progress: Column | None = None
        progress = f.get("acquire/progress")
        if isinstance(progress, h5py.Dataset) and "fields" in progress.attrs:
            self.progress_fields = list(json.loads(text(progress.attrs["fields"])))
            self._progress = _column(progress, self.fd)
        self.steps: tuple[Step, ...]
        try:
            self.steps = read_schedule(f, self.path)
        except InputError:  # none, or of another version: the page shows no step, nothing else changes
            self.steps = ()
        if all(isinstance(c, _PreadColumn) for c in self._all_columns()):
            self._h5.close()  # everything is read by pread: hold no HDF5 handle on a file being written
            self._handle.close()

    def _all_columns(self) -> list[Column]:
        return [*self.columns.values(), *self.events.values(), *([self._progress] if self._progress else [])]

    @property
    def identity(self) -> tuple[Any, ...]:
        """What stays the same across the versions of one run (growth, resume, close)."""
        return (self.attrs.get("created_utc"), self.attrs.get("protocol"), self.dt, self.t0, tuple(self.channels))

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", ""))

    def progress(self) -> dict[str, float]:
        """The progress record (field -> value); empty for a run file without one (imported: all rows valid).

        Read until two reads agree, so a record the writer is overwriting at that moment is not mixed up.
        """
        if self._progress is None:
            return {}
        values = self._progress.read(0, len(self.progress_fields))
        for _ in range(3):
            again = self._progress.read(0, len(self.progress_fields))
            if np.array_equal(values, again, equal_nan=True):
                break
            values = again
        return dict(zip(self.progress_fields, (float(v) for v in values)))

    def valid_rows(self, progress: Mapping[str, float]) -> int:
        """Rows of /aligned that hold data: the progress record's count while running, else all of them."""
        rows = progress.get("aligned_rows")
        return self.capacity if rows is None or not np.isfinite(rows) else int(min(max(rows, 0), self.capacity))

    def event_rows(self, progress: Mapping[str, float]) -> int:
        if not self.events:
            return 0
        length = self.events["time"].length
        rows = progress.get("event_rows")
        return length if rows is None or not np.isfinite(rows) else int(min(max(rows, 0), length))

    def read_channels(self, start: int, stop: int) -> np.ndarray:
        """Rows [start, stop) of every channel as float64, shape (channels, rows)."""
        out = np.empty((len(self.columns), max(0, min(stop, self.capacity) - start)))
        for i, column in enumerate(self.columns.values()):
            out[i] = column.read(start, stop)
        return out

    def read_events(self, start: int, stop: int) -> list[dict[str, Any]]:
        """Events [start, stop) as dicts time (s), cycle, kind, detail, step, reason (a file written before a
        column existed: as complete_events fills it)."""
        if not self.events or stop <= start:
            return []
        cols = complete_events({c: column.read(start, stop) for c, column in self.events.items()}, stop - start)
        return [{"time": float(t), "cycle": int(c), "kind": text(k).rstrip("\x00"), "detail": text(d).rstrip("\x00"),
                 "step": int(s), "reason": text(r).rstrip("\x00")} for t, c, k, d, s, r in zip(*cols.values())]

    def replaced(self) -> bool:
        """Whether the run's name now points to another file (the writer's os.replace), or to none."""
        try:
            stat = os.stat(self.path)
        except OSError:
            return True
        return (stat.st_dev, stat.st_ino) != self.inode

    def close(self) -> None:
        h5 = getattr(self, "_h5", None)
        if h5 is not None and h5.id.valid:
            h5.close()
        handle = getattr(self, "_handle", None)
        if handle is not None:
            handle.close()
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
