"""Crash-safe run-file writer: raw streams, events and the contract's /aligned grid, written as data arrives.

Crash safety without trusting HDF5 to survive a kill mid-write: every dataset is created at its full
planned capacity when the file is made (contiguous, allocated and filled with NaN, `/aligned/time` with
the whole grid). While the run goes, the file's structure (its metadata) never changes and HDF5 is not
even open: the writer only overwrites the datasets' bytes inside allocated space through a shared memory
mapping of the file (the page cache, which outlives a killed process), then writes the progress record
(`/acquire/progress`, one 8-byte word per counter); with `durable=True` (hardware) it msyncs and fsyncs
before and after the progress record, so a power loss keeps the same order. A process killed at any moment
therefore leaves a file whose structure was complete and flushed before the run started: it opens, its
`/aligned` grid is uniform, samples not yet written are NaN ("not measured"), and the progress record says
how far the data is valid (at most `flush_every_s` of data behind the kill). Growing beyond the capacity,
resuming, and closing build a new file next to the old one and `os.replace` it in one step, so there is
always exactly one complete file under the run's name; an interrupted rebuild removes its half-made copy.
Closing also compacts (exact lengths, compressed). One run per file is the caller's lock (acquire/lock.py).

A full disk (or the process's file-size limit) while growing or closing leaves the file as it was, readable up to
its last flush, with root attribute `status` "aborted" where HDF5 can still write that in place, and raises
benchlab.outputs.OutputError: one line naming the file (the CLI's exit 1).
"""

from __future__ import annotations

import functools
import json
import logging
import mmap
import os
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from benchlab.jit import njit

from benchlab.outputs import OutputError, is_no_space, no_space
from benchlab.runfile.compressed import compressed_dataset
from benchlab.runfile.read import complete_events, read_progress, text
from benchlab.runfile.schema import EVENT_FIELDS, SCHEMA, aligned_description

log = logging.getLogger(__name__)

_EPS = 1e-9
#: The running file's `status` as HDF5 stores a variable-length string: a global heap object (its size as 8 bytes,
#: then the bytes), written with the attributes at the start of the file. On a full disk the writer overwrites these
#: 7 bytes with "aborted" through the mapping (HDF5 would allocate a new heap object: a full disk has no room).
RUNNING_ON_DISK = struct.pack("<Q", 7) + b"running"
#: How far into the file the attributes' heap objects are searched for it.
STATUS_SEARCH_BYTES = 1 << 20
#: Every this many flushes the mapping's pages leave the process (madvise DONTNEED): a shared file mapping keeps
#: every page written in the process's resident memory until then, which grows with the run (issue 47); the bytes
#: stay in the page cache and the file, dirty ones written back by the kernel, so a killed process loses nothing.
RELEASE_EVERY_FLUSHES = 60
#: /truth rows written together (64 kB a column): a pwrite into the page cache's large folios of the run file costs
#: about the same for 1,000 rows as for 8,192 (ext4 walks every block of the folio written into), 42 µs a column.
TRUTH_BATCH_ROWS = 8192


@dataclass(frozen=True)
class StreamSpec:
    """One raw stream as a device delivers it: columns (name, units) besides `time`, rate bound, hold."""

    name: str
    columns: tuple[tuple[str, str], ...]
    rate_hz: float
    hold_s: float

    @functools.cached_property
    def names(self) -> tuple[str, ...]:
        return tuple(c for c, _ in self.columns)


@dataclass(frozen=True)
class AlignedSource:
    """An /aligned channel taken from one raw column (times `scale`), held on the grid as its stream says."""

    channel: str
    stream: str
    column: str
    scale: float = 1.0


Derive = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]


@dataclass(frozen=True)
class Layout:
    """What a run file holds: the raw streams, how /aligned is built from them, the grid step."""

    streams: tuple[StreamSpec, ...]
    sources: tuple[AlignedSource, ...]
    aligned_units: Mapping[str, str]  # every /aligned channel (time excluded) -> units, in file order
    derive: Derive | None = None  # channels computed on the grid from the held ones (friction power, means)
    dt: float = 0.01

    def stream(self, name: str) -> StreamSpec:
        return next(s for s in self.streams if s.name == name)


class _Readings:
    """Readings of one stream in arrival order, single rows or blocks, handed out as one (N, 1 + columns) array."""

    def __init__(self, columns: int) -> None:
        self.columns = columns
        self.flat: list[float] = []  # single readings since the last part, one after the other: time, values...
        self.parts: list[Any] = []  # in order: (N, 1 + columns) arrays and (times, values) blocks
        self._count = 0  # readings in parts
        self._none = np.empty((0, 1 + columns))

    def add(self, t: "float | np.ndarray", row: "Sequence[float] | np.ndarray") -> None:
        """One reading (`t` a number, `row` its values) or a block (`t` N times, `row` an (N, columns) array)."""
        if isinstance(t, np.ndarray):
            self.add_block(t, row)
        elif len(row) == self.columns:
            self.flat.append(t)
            self.flat.extend(row)
        else:
            raise ValueError(f"{len(row)} values for a stream of {self.columns} columns")

    def add_block(self, t: np.ndarray, row: np.ndarray) -> None:
        """A block of readings: `t` N times, `row` an (N, columns) array (copied when taken)."""
        self._close_rows()
        self.parts.append((t, row))
        self._count += len(t)

    def add_rows(self, block: np.ndarray) -> None:
        """Readings already as (N, 1 + columns) rows, time first (kept as they are: not to be changed after)."""
        self._close_rows()
        self.parts.append(np.ascontiguousarray(block, dtype=float))
        self._count += len(block)

    def take(self) -> np.ndarray:
        """Everything added since the last take, in order, and forget it."""
        self._close_rows()
        parts, self.parts = self.parts, []
        count, self._count = self._count, 0
        if len(parts) == 1 and isinstance(parts[0], np.ndarray):
            return parts[0]
        if not parts:
            return self._none
        out = np.empty((count, 1 + self.columns))
        a = 0
        for part in parts:
            if isinstance(part, tuple):
                t, row = part
                out[a:a + len(t), 0] = t
                out[a:a + len(t), 1:] = row
                a += len(t)
            else:
                out[a:a + len(part)] = part
                a += len(part)
        return out

    def __len__(self) -> int:
        return self._count + len(self.flat) // (1 + self.columns)

    def __bool__(self) -> bool:
        return bool(self.parts or self.flat)

    def _close_rows(self) -> None:
        if self.flat:
            block = np.array(self.flat, dtype=float).reshape(-1, 1 + self.columns)
            self.flat = []
            self.parts.append(block)
            self._count += len(block)


def _str_array(values: Sequence[str], length: int) -> np.ndarray:
    return np.array([v.encode("utf-8", "replace")[:length] for v in values], dtype=f"S{length}")


def _column_of(values: Sequence[Any], dtype: np.dtype) -> np.ndarray:
    """Values as a stored column of `dtype` (text cut to its fixed length in UTF-8)."""
    return _str_array(values, dtype.itemsize) if dtype.kind == "S" else np.asarray(values, dtype=dtype)


class AlignedBuilder:
    """Turns time-stamped readings into rows of the uniform grid: hold until the next reading or `hold_s`.

    A reading at time t counts for grid points t_k >= t until the stream's next reading, but never longer
    than the stream's `hold_s` (its expected period plus a margin): a missing reading is NaN, nothing is
    carried across a drop-out. A reading whose value is NaN (sensor fault) is NaN on the grid.
    """

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.dt = layout.dt
        self.rows = 0  # grid rows finalised
        sourced = [src.channel for src in layout.sources]
        #: the grid's channels in one matrix: the stored ones in file order, then sourced ones that are not stored
        self.channels = list(layout.aligned_units) + [c for c in sourced if c not in layout.aligned_units]
        self._derived = [(j, c) for j, c in enumerate(self.channels) if c not in sourced]
        self._sourced = [(j, c) for j, c in enumerate(self.channels) if c in sourced]
        index = {c: j for j, c in enumerate(self.channels)}
        self._held = [spec for spec in layout.streams if any(src.stream == spec.name for src in layout.sources)]
        self._holds = np.array([spec.hold_s for spec in self._held], dtype=float)
        #: per held stream, a row per channel it gives: its column in the readings, its grid column, its scale
        self._plans = tuple(np.array([(1 + spec.names.index(src.column), index[src.channel], src.scale)
                                      for src in layout.sources if src.stream == spec.name], dtype=float)
                            for spec in self._held)
        self._pending = {spec.name: _Readings(len(spec.columns)) for spec in self._held}  # held streams only
        self._held_at = [layout.streams.index(spec) for spec in self._held]
        #: the last reading of each held stream before the grid's next row (time -inf: none yet), updated in place
        self._carries = tuple(np.array([-np.inf] + [np.nan] * len(spec.columns)) for spec in self._held)

    def add(self, stream: str, t: "float | np.ndarray", row: "Sequence[float] | np.ndarray") -> None:
        """One reading of `stream`, or a block of them (`t` an array, `row` an (N, columns) array)."""
        if stream in self._pending:  # a stream no /aligned channel comes from is not held
            self._pending[stream].add(t, row)

    def add_rows(self, stream: str, rows: np.ndarray) -> None:
        """Readings of `stream` as (N, 1 + columns) rows, time first."""
        if stream in self._pending:
            self._pending[stream].add_rows(rows)

    def finalise(self, until_row: int) -> dict[str, np.ndarray]:
        """Channels for grid rows [rows, until_row) (time included); later readings stay pending."""
        return self.finalise_matrix(until_row)[1]

    def finalise_matrix(self, until_row: int, fresh: Sequence[np.ndarray] | None = None
                        ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """`finalise`, with the rows also as one matrix whose columns are `channels`. `fresh`: the newest readings
        of every stream of the layout, in its order, as (N, 1 + columns) float rows (as if added just before)."""
        k0, k1 = self.rows, max(self.rows, until_row)
        grid = np.empty((k1 - k0, len(self.channels)))
        out: dict[str, np.ndarray] = {"time": np.arange(k0, k1) * self.dt}
        pending = [self._pending[spec.name] for spec in self._held]
        if fresh is not None:
            for p, i in zip(pending, self._held_at):
                if p or k1 == k0:  # behind readings still pending (rare), or no grid row to take them
                    p.add_rows(fresh[i])
        if k1 > k0:  # else no grid rows to fill: the readings stay pending
            readings = tuple(p.take() if fresh is None or p else fresh[i] for p, i in zip(pending, self._held_at))
            rest = _hold_streams(self._carries, readings, k0, self.dt, self._holds, self._plans, grid)
            for i in np.flatnonzero(rest):  # readings after the last row stay pending; disordered ones are sorted
                data = readings[i]
                if rest[i] < 0:  # readings out of time order: sorted (stable) after the carried one, then held
                    data = np.concatenate([self._carries[i][None, :], data])
                    data = data[np.argsort(data[:, 0], kind="stable")]
                    self._carries[i][:] = data[0]
                    data = data[1:]
                    used = _hold_on_grid(self._carries[i], data, k0, self.dt, self._holds[i], self._plans[i], grid)
                    if used:
                        self._carries[i][:] = data[used - 1]
                else:
                    used = len(data) - rest[i]
                if used < len(data):
                    pending[i].add_rows(data[used:])
        for j, channel in self._sourced:  # contiguous (a column view is too only for one row): one compiled signature
            out[channel] = np.ascontiguousarray(grid[:, j])  # for `derive`'s kernels, whatever the rows
        if self.layout.derive is not None:
            derived = self.layout.derive(out)
            out.update(derived)
            for j, channel in self._derived:
                grid[:, j] = derived[channel]
        self.rows = k1
        return grid, out


@njit(cache=True, nogil=True)
def _hold_streams(carries: tuple, readings: tuple, k0: int, dt: float, holds: np.ndarray, plans: tuple,
                  grid: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """_hold_on_grid for each held stream, its carried reading then moved on to its newest used one. Returns per
    stream how many readings lie after the grid's last row (-1: not in time order, nothing done for it)."""
    rest = np.empty(len(readings), np.int64)
    for s in range(len(readings)):
        used = _hold_on_grid(carries[s], readings[s], k0, dt, holds[s], plans[s], grid)
        if used > 0:
            carry, newest = carries[s], readings[s]
            for c in range(carry.shape[0]):  # element by element: a row assignment compiles numba's shape error
                carry[c] = newest[used - 1, c]
        rest[s] = -1 if used < 0 else readings[s].shape[0] - used
    return rest


@njit(cache=True, nogil=True)
def _hold_on_grid(carry: np.ndarray, readings: np.ndarray, k0: int, dt: float, hold_s: float, plan: np.ndarray,
                  grid: np.ndarray) -> int:  # pragma: no cover - compiled
    """Grid rows k0, k0+1, ... (time k·dt, as many as `grid` has) from time-ordered readings (time, values...) that
    follow `carry`, the newest reading before row k0 (time -inf: none): each row holds the newest reading at or
    before it, NaN when it is `hold_s` old or older; per `plan` row (column, grid column, scale) the reading's
    column times scale goes to the grid column. Returns how many of `readings` lie at or before the last row
    (-1, nothing written, if they are not in time order)."""
    n = readings.shape[0]
    last = carry[0]
    for j in range(n):
        if readings[j, 0] < last:
            return -1
        last = readings[j, 0]
    j = 0
    for k in range(k0, k0 + grid.shape[0]):
        t = k * dt
        while j < n and readings[j, 0] <= t + _EPS:
            j += 1
        row = carry if j == 0 else readings[j - 1]
        held = t - row[0] < hold_s + _EPS
        for i in range(plan.shape[0]):
            grid[k - k0, int(plan[i, 1])] = row[int(plan[i, 0])] * plan[i, 2] if held else np.nan
    return j


class RunWriter:
    """Writes one run file as the data arrives; see the module docstring for the crash-safety scheme."""

    def __init__(self, path: "str | os.PathLike[str]", layout: Layout, *, protocol: str,
                 attrs: Mapping[str, Any] | None = None, schedule: Sequence[Mapping[str, Any]] = (),
                 schedule_units: Mapping[str, str] | None = None, planned_s: float = 3600.0,
                 flush_every_s: float = 1.0, state_fields: Sequence[str] = (), durable: bool = False,
                 truth_units: Mapping[str, str] | None = None, _resume: bool = False) -> None:
        self.path = Path(path)
        self.layout = layout
        self.protocol = protocol
        self.flush_every_s = flush_every_s
        self.state_fields = tuple(state_fields)
        self.state: dict[str, float] = {k: float("nan") for k in self.state_fields}
        self.builder = AlignedBuilder(layout)
        self._raw = {s.name: _Readings(len(s.columns)) for s in layout.streams}
        self._raw_rows = {s.name: 0 for s in layout.streams}
        self._events: list[tuple[float, int, str, str, int, str]] = []  # rows of /events, columns as EVENT_FIELDS
        self._event_rows = 0
        self._last_flush_t = 0.0
        self._now = 0.0
        self.flushes = 0
        self.durable = durable
        self._fd: int | None = None
        self._status_at: int | None = None  # where the status "running" lies in the file (see RUNNING_ON_DISK)
        self._mm: np.memmap | None = None
        self._views: dict[str, np.ndarray] = {}
        #: the simulated bench's /truth: its columns (time excluded) and units, on the /aligned grid and capacity
        self.truth_units = dict(truth_units or {})
        self._truth_end = 0  # first /truth row not written into this file by `put_truth`
        self._truth_batch: list[tuple[int, np.ndarray]] = []  # rows handed over, not written yet (first row, rows)
        if _resume:
            return
        capacity = self._capacities(planned_s)
        self._build(self.path, capacity, {
            "attrs": {"schema": SCHEMA, "status": "running", "protocol": protocol, **dict(attrs or {})},
            "schedule": list(schedule), "schedule_units": dict(schedule_units or {})}, None)
        self._open()

    # -- public API --------------------------------------------------------------------------------
    def add(self, stream: str, t: "float | np.ndarray", row: "Sequence[float] | np.ndarray") -> None:
        """One reading of `stream` at run time `t` (s): values in the stream's column order (NaN = no number);
        or a block of readings: `t` an array of N times, `row` an (N, columns) array."""
        readings = self._raw[stream]
        if isinstance(t, np.ndarray) or len(row) != readings.columns:
            readings.add(t, row)  # a block, or a row of the wrong length (refused there)
        else:  # _Readings.add without a second call: the runner adds a reading at a time
            readings.flat.append(t)
            readings.flat.extend(row)

    def event(self, t: float, kind: str, cycle: int = -1, detail: str = "", *, step: int = -1,
              reason: str = "") -> None:
        """An entry of the events table (cycle start, engagement, interlock, fault, drop-out, ...); `step` is the
        row of /schedule it belongs to (-1: none), `reason` what a program matches (EVENT_FIELDS), `detail` is
        for people."""
        self._events.append((float(t), int(cycle), kind, detail, int(step), reason))

    def put_truth(self, first_row: int, states: np.ndarray) -> None:
        """Rows `first_row` … of /truth (an (n, columns) array, columns in `truth_units`' order): the simulated
        bench's true states once final, written into the file as they come, TRUTH_BATCH_ROWS at a time (and the
        rest when it closes), each row once."""
        self._truth_batch.append((first_row, states))
        if sum(len(rows) for _, rows in self._truth_batch) >= TRUTH_BATCH_ROWS:
            self._write_truth()

    def _write_truth(self) -> None:
        """The /truth rows handed over into the file with `os.pwrite`, one write a column for each contiguous run of
        them (the page cache, as the mapping's bytes, but none of them held in the process's memory); rows beyond
        the capacity wait for the file to grow."""
        runs: list[tuple[int, list[np.ndarray]]] = []
        for first_row, states in self._truth_batch:
            if runs and runs[-1][0] + sum(len(part) for part in runs[-1][1]) == first_row:
                runs[-1][1].append(states)
            else:
                runs.append((first_row, [states]))
        self._truth_batch = []
        capacity = self._capacity("truth/time")
        for first_row, parts in runs:
            states = np.concatenate(parts) if len(parts) > 1 else parts[0]
            fits = max(min(len(states), capacity - first_row), 0)
            if fits < len(states):
                self._truth_batch.append((first_row + fits, states[fits:]))
            for j, name in enumerate(self.truth_units):
                offset = self._where[f"truth/{name}"][0] + 8 * first_row
                try:
                    os.pwrite(self._fd, np.ascontiguousarray(states[:fits, j], dtype="<f8").tobytes(), offset)
                except OSError as exc:  # a full disk: the run file as its last flush left it, as for any write
                    if is_no_space(exc):
                        raise self._aborted_for_space() from None
                    raise
            self._truth_end = max(self._truth_end, first_row + fits)

    def advance(self, now: float, force: bool = False) -> bool:
        """Data up to `now` is complete; flush once `flush_every_s` of data has accumulated. True if flushed."""
        self._now = max(self._now, now)
        if force or now - self._last_flush_t >= self.flush_every_s - _EPS:
            self.flush(now)
            return True
        return False

    def flush(self, now: float | None = None) -> None:
        """Write everything up to `now` into the file, then commit the progress record."""
        now = self._now if now is None else now
        assert self._fd is not None
        until_row = int(np.floor(now / self.layout.dt + _EPS)) + 1
        self._ensure_capacity(until_row)
        raw = tuple(readings.take() for readings in self._raw.values())  # every stream: one compiled signature
        k0 = self.builder.rows
        grid, _ = self.builder.finalise_matrix(until_row, raw)
        _scatter(self._words, self._aligned_words, k0, grid)
        _scatter_streams(self._words, self._stream_words, np.array(list(self._raw_rows.values())), raw)
        for name, data in zip(self._raw, raw):
            self._raw_rows[name] += len(data)
        if self._events:
            a, ev = self._event_rows, self._events
            for j, (name, (dtype, _, _)) in enumerate(EVENT_FIELDS.items()):
                self._put(f"events/{name}", a, _column_of([e[j] for e in ev], np.dtype(dtype)))
            self._event_rows = a + len(ev)
            self._events = []
        if self.durable:  # power loss too: data on disk before the progress record that covers it
            self._mm.flush()
            os.fsync(self._fd)
        self._put("acquire/progress", 0, self._progress_vector(now))
        if self.durable:
            self._mm.flush()
            os.fsync(self._fd)
        self._last_flush_t = now
        self.flushes += 1
        if self.flushes % RELEASE_EVERY_FLUSHES == 0:
            self._mm._mmap.madvise(mmap.MADV_DONTNEED)  # noqa: SLF001 - see RELEASE_EVERY_FLUSHES
        log.debug("flush %d: %.3f s, %d grid rows, %d events in the file", self.flushes, now, self.builder.rows,
                  self._event_rows)

    def close(self, status: str = "complete", attrs: Mapping[str, Any] | None = None) -> None:
        """Flush, then replace the file by its compact, compressed form with root attribute `status` (/truth cut,
        like /aligned, at the grid rows flushed)."""
        if self._fd is None:
            return
        try:
            self.flush()
            if self._truth_batch:
                self._write_truth()
            self._close_fd()
            self._rebuild(None, compact=True, status=status, attrs=attrs)
        except OutputError:
            raise self._aborted_for_space() from None

    def set_status(self, status: str) -> None:
        """The closed file's root attribute `status` (a stop that came while it was being compacted ends it so)."""
        with h5py.File(self.path, "r+") as f:
            f.attrs["status"] = status

    @property
    def rows(self) -> int:
        return self.builder.rows

    # -- resume ------------------------------------------------------------------------------------
    @classmethod
    def resume(cls, path: "str | os.PathLike[str]", layout: Layout, *, extra_s: float,
               flush_every_s: float = 1.0, truth_units: Mapping[str, str] | None = None) -> "RunWriter":
        """Reopen a run file ('running' after a crash, or 'aborted'): keep its valid data (/truth's rows up to the
        progress record too), add room for `extra_s`."""
        path = Path(path)
        with h5py.File(path, "r") as src:
            progress = read_progress(src)
            protocol = str(src.attrs.get("protocol", ""))
            fields = [f for f in json.loads(src["acquire/progress"].attrs["fields"]) if f.startswith("state/")]
            state_fields = [f[len("state/"):] for f in fields]
            writer = cls(path, layout, protocol=protocol, flush_every_s=flush_every_s,
                         state_fields=state_fields, truth_units=truth_units, _resume=True)
            writer.state = {k: progress.get(f"state/{k}", float("nan")) for k in state_fields}
            rows = int(progress["aligned_rows"])
            writer.builder.rows = rows
            writer._event_rows = int(progress["event_rows"])
            writer._raw_rows = {s.name: int(progress.get(f"rows/{s.name}", 0)) for s in layout.streams}
            t_end = (rows - 1) * layout.dt if rows else 0.0
            writer._now = writer._last_flush_t = t_end
            capacity = writer._capacities(t_end + extra_s)
        writer._rebuild(capacity, compact=False, status="running", attrs=None)
        writer._open()
        return writer

    # -- internals ---------------------------------------------------------------------------------
    def _capacities(self, planned_s: float) -> dict[str, int]:
        seconds = planned_s * 1.1 + 60.0
        caps = {"aligned": int(np.ceil(seconds / self.layout.dt)) + 1, "events": int(seconds / 5) + 1000}
        for s in self.layout.streams:
            caps[f"raw/{s.name}"] = int(np.ceil(seconds * s.rate_hz)) + 100
        return self._with_truth(caps)

    def _with_truth(self, capacity: dict[str, int]) -> dict[str, int]:
        """`capacity` with /truth's, /aligned's own (the same grid), where the run has a /truth."""
        return {**capacity, "truth": capacity["aligned"]} if self.truth_units else capacity

    def _rebuild(self, capacity: Mapping[str, int] | None, *, compact: bool, status: str,
                 attrs: Mapping[str, Any] | None) -> None:
        """Replace the file by a rebuilt copy of its valid data (see _copy): built next to it, then os.replace."""
        tmp = _tmp(self.path)
        try:
            # no chunk cache: every slice is read once, and a cache per dataset held open (1 MB each by default) kept
            # 340 MB resident when a 3.5 h aborted run was resumed
            with h5py.File(self.path, "r", rdcc_nbytes=0) as src:
                self._copy(src, tmp, capacity, compact=compact, status=status, attrs=attrs)
            os.replace(tmp, self.path)
        except Exception as exc:
            if is_no_space(exc):  # the run file as it was: its data up to the last flush
                raise no_space(self.path, "the run file could not be rebuilt; it holds the data up to its last "
                                          f"flush at {self._last_flush_t:.1f} s") from None
            raise
        finally:  # interrupted (Ctrl-C, a full disk): no half-made copy is left beside the run file
            tmp.unlink(missing_ok=True)

    def _open(self) -> None:
        """Note where each dataset's bytes live, close HDF5, and keep a plain file descriptor for writing."""
        self._where: dict[str, tuple[int, np.dtype, int]] = {}
        with h5py.File(self.path, "r", locking=False) as f:
            def visit(name: str, obj: Any) -> None:
                if isinstance(obj, h5py.Dataset):
                    offset = obj.id.get_offset()
                    if offset is None or obj.chunks is not None or obj.compression:
                        raise RuntimeError(f"{name}: not a contiguous allocated dataset")
                    self._where[name] = (offset, obj.dtype.newbyteorder("<"), obj.shape[0])
            f.visititems(visit)
        self._fd = os.open(self.path, os.O_RDWR)
        self._mm = np.memmap(self.path, dtype=np.uint8, mode="r+")
        whole = np.asarray(self._mm)  # a plain ndarray view of the mapping: slicing it skips memmap's bookkeeping
        self._views = {name: whole[off:off + cap * dt.itemsize].view(dt)
                       for name, (off, dt, cap) in self._where.items()}
        self._words = whole[:len(whole) // 8 * 8].view("<f8")  # the file as 8-byte words: datasets start on one
        self._aligned_words = np.array([self._word(f"aligned/{name}") for name in self.layout.aligned_units])
        self._raw_capacity = [self._capacity(f"raw/{s.name}/time") for s in self.layout.streams]
        self._stream_words = tuple(np.array([self._word(f"raw/{s.name}/{c}") for c in ("time", *s.names)])
                                   for s in self.layout.streams)
        head = whole[:STATUS_SEARCH_BYTES].tobytes()
        at = head.find(RUNNING_ON_DISK)
        unique = at >= 0 and head.find(RUNNING_ON_DISK, at + 1) < 0
        self._status_at = at + 8 if unique else None

    def _word(self, name: str) -> int:
        """Index in the file's 8-byte words of float64 dataset `name`'s first value (the file aligns datasets)."""
        offset, dtype, _ = self._where[name]
        if dtype != np.dtype("<f8") or offset % 8:
            raise RuntimeError(f"{name}: not an 8-byte aligned float64 dataset")
        return offset // 8

    def _aborted_for_space(self) -> OutputError:
        """The run file as its last flush left it, its status "running" overwritten by "aborted" in place (the bytes
        found by `_status_at` when the file was opened; nothing allocated): the one-line error to raise."""
        self._close_fd()
        marked = "status left 'running'"
        if self._status_at is not None:
            status = np.memmap(self.path, dtype=np.uint8, mode="r+", offset=self._status_at, shape=(7,))
            status[:] = np.frombuffer(b"aborted", dtype=np.uint8)
            status.flush()
            del status
            with h5py.File(self.path, "r", locking=False) as f:
                marked = f"status {text(f.attrs.get('status'))}"
        return no_space(self.path, f"run aborted, {marked}; the file holds the data up to its last flush at "
                                   f"{self._last_flush_t:.1f} s")

    def _close_fd(self) -> None:
        if self._fd is not None:
            self._views, self._words = {}, None
            if self._mm is not None:
                if self.durable:  # else the page cache holds the bytes for any reader, a killed process or not
                    self._mm.flush()
                self._mm._mmap.close()  # noqa: SLF001 - unmap now, not at garbage collection
                self._mm = None
            os.close(self._fd)
            self._fd = None

    def _capacity(self, name: str) -> int:
        return self._where[name][2]

    def _put(self, name: str, start: int, values: np.ndarray) -> None:
        """Store into the dataset's bytes through the shared mapping (the page cache: survives a killed process)."""
        view = self._views[name]
        if start + len(values) > len(view):
            raise RuntimeError(f"{name}: capacity {len(view)} exceeded")
        view[start:start + len(values)] = values

    def _progress_fields(self) -> list[str]:
        return (["aligned_rows", "event_rows", "t_data", "flushes"] + [f"rows/{s.name}" for s in self.layout.streams]
                + [f"state/{k}" for k in self.state_fields])

    def _progress_vector(self, now: float) -> np.ndarray:
        values = [self.builder.rows, self._event_rows, now, self.flushes + 1]
        values += [self._raw_rows[s.name] for s in self.layout.streams]
        values += [self.state.get(k, np.nan) for k in self.state_fields]
        return np.asarray(values, dtype=float)

    def _ensure_capacity(self, until_row: int) -> None:
        """Grow the file (rebuilt at twice what is needed) if what the next flush writes would not fit."""
        if (until_row <= self._capacity("aligned/time")
                and self._event_rows + len(self._events) <= self._capacity("events/time")
                and all(self._raw_rows[name] + len(readings) <= capacity
                        for (name, readings), capacity in zip(self._raw.items(), self._raw_capacity))):
            return
        need = {"aligned": until_row, "events": self._event_rows + len(self._events)}
        have = {"aligned": self._capacity("aligned/time"), "events": self._capacity("events/time")}
        for name in self._raw:
            need[f"raw/{name}"] = self._raw_rows[name] + len(self._raw[name])
            have[f"raw/{name}"] = self._capacity(f"raw/{name}/time")
        capacity = self._with_truth({k: max(have[k], 2 * need[k]) for k in have})
        self._close_fd()
        self._rebuild(capacity, compact=False, status="running", attrs=None)
        self._open()

    def _build(self, path: Path, capacity: Mapping[str, int], meta: Mapping[str, Any],
               data: Mapping[str, np.ndarray] | None) -> None:
        """Create a file with every dataset at `capacity` (None: exact length of `data`)."""
        data = data or {}
        compact = capacity is None
        tmp = _tmp(path)
        try:
            self._write_file(tmp, capacity, meta, data, compact)
            os.replace(tmp, path)
        except Exception as exc:
            if is_no_space(exc):
                raise no_space(path, "no room for the file; nothing written") from None
            raise
        finally:  # interrupted: no half-made file left
            tmp.unlink(missing_ok=True)

    def _write_file(self, tmp: Path, capacity: Mapping[str, int] | None, meta: Mapping[str, Any],
                    data: Mapping[str, np.ndarray], compact: bool) -> None:
        """Write the whole file at `tmp`: attributes, /aligned, /raw, /events, /schedule, /acquire."""
        aligned = {} if compact else {"alignment_threshold": 1, "alignment_interval": 8}  # see _word
        with h5py.File(tmp, "w", locking=False, **aligned) as f:
            f.attrs.update({k: v for k, v in meta["attrs"].items() if v is not None})
            self._write_group(f, "aligned", {"time": "s", **self.layout.aligned_units},
                              capacity, data, compact, "aligned")
            f["aligned"].attrs["dt"] = float(self.layout.dt)
            sources = describe_layout(self.layout)["aligned"]
            for name, ds in f["aligned"].items():
                ds.attrs["description"] = aligned_description(name, sources.get(name))
            raw = f.create_group("raw")
            for s in self.layout.streams:
                self._write_group(raw, s.name, {"time": "s", **dict(s.columns)}, capacity, data, compact,
                                  f"raw/{s.name}")
                raw[s.name].attrs.update(rate_hz=s.rate_hz, hold_s=s.hold_s)
            ev = f.create_group("events")
            n_ev = len(data.get("events/time", ())) if compact else capacity["events"]
            for name, (dtype, units, fill) in EVENT_FIELDS.items():
                arr = np.full(n_ev, fill, dtype=dtype)
                src = data.get(f"events/{name}")
                if src is not None:
                    arr[:len(src)] = src[:n_ev]
                ds = _dataset(ev, name, arr, compact)
                ds.attrs["units"] = units
            self._write_schedule(f, meta["schedule"], meta["schedule_units"])
            acq = f.create_group("acquire")
            fields = self._progress_fields()
            prog = np.asarray(meta.get("progress", [0, 0, 0, 0] + [0] * len(self.layout.streams)
                                       + [np.nan] * len(self.state_fields)), dtype=float)
            ds = acq.create_dataset("progress", data=prog, track_times=False)
            ds.attrs["fields"] = json.dumps(fields)
            ds.attrs["units"] = "1"
            acq.attrs["layout"] = json.dumps(describe_layout(self.layout))
            if self.truth_units:
                self._write_group(f, "truth", {"time": "s", **self.truth_units}, capacity, data, compact, "truth")
            f.flush()

    def _write_group(self, parent: h5py.Group, name: str, columns: Mapping[str, str], capacity, data,
                     compact: bool, prefix: str) -> None:
        group = parent.create_group(name)
        n = len(data.get(f"{prefix}/time", ())) if compact else capacity[prefix]
        for col, units in columns.items():
            src = data.get(f"{prefix}/{col}")
            grid = self.layout.dt if col == "time" and prefix in ("aligned", "truth") else None
            if not compact:
                ds = _capacity_dataset(group, col, n, None if grid else src, grid)
            elif src is not None and len(src) == n:  # already exactly what is stored: no copy
                ds = _dataset(group, col, src, compact)
            else:
                arr = np.arange(n) * grid if grid else np.full(n, np.nan)
                if src is not None:
                    arr[:len(src)] = src[:n]
                ds = _dataset(group, col, arr, compact)
            ds.attrs["units"] = units

    def _write_schedule(self, f: h5py.File, schedule: Sequence[Mapping[str, Any]], units: Mapping[str, str]) -> None:
        group = f.create_group("schedule")
        group.attrs["steps_json"] = json.dumps(list(schedule), default=str)
        if not schedule:
            return
        keys = list(schedule[0])
        for key in keys:
            values = [row.get(key) for row in schedule]
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
                arr = np.asarray(values, dtype=float)
            else:
                arr = _str_array([json.dumps(v) if not isinstance(v, str) else v for v in values], 200)
            ds = group.create_dataset(key, data=arr, track_times=False)
            ds.attrs["units"] = units.get(key, "")

    def _copy(self, src: h5py.File, dest: Path, capacity, *, compact: bool, status: str,
              attrs: Mapping[str, Any] | None) -> None:
        """Rebuild the file: valid data of `src` (per its progress record) at new capacities."""
        progress = read_progress(src)
        data: dict[str, np.ndarray] = {}
        rows = int(progress["aligned_rows"])
        for name in ["time", *self.layout.aligned_units]:
            data[f"aligned/{name}"] = _Rows(src["aligned"][name], rows)
        for s in self.layout.streams:
            n = int(progress.get(f"rows/{s.name}", 0))
            for col in ("time", *s.names):
                data[f"raw/{s.name}/{col}"] = _Rows(src["raw"][s.name][col], n)
        if self.truth_units and "truth" in src:  # growing: the rows this writer put beyond the progress record too
            n = rows if compact else max(rows, self._truth_end)
            for col in ("time", *self.truth_units):
                if col in src["truth"]:
                    data[f"truth/{col}"] = _Rows(src["truth"][col], n)
        n_ev = int(progress["event_rows"])
        stored = {name: ds[:n_ev] for name, ds in src["events"].items() if name in EVENT_FIELDS}
        data.update({f"events/{name}": column for name, column in complete_events(stored, n_ev).items()})
        meta_attrs = {k: v for k, v in src.attrs.items()}
        meta_attrs["status"] = status
        meta_attrs.update(dict(attrs or {}))
        schedule = json.loads(src["schedule"].attrs.get("steps_json", "[]"))
        units = {k: str(ds.attrs.get("units", "")) for k, ds in src["schedule"].items()}
        fields = json.loads(src["acquire/progress"].attrs["fields"])
        vec = self._progress_vector(progress["t_data"])
        by_name = dict(zip(self._progress_fields(), vec))
        for k, v in zip(fields, src["acquire/progress"][()]):
            by_name.setdefault(k, v)
        by_name.update({k: progress[k] for k in ("aligned_rows", "event_rows", "t_data", "flushes")})
        for s in self.layout.streams:
            by_name[f"rows/{s.name}"] = progress.get(f"rows/{s.name}", 0)
        for k in self.state_fields:
            by_name[f"state/{k}"] = self.state.get(k, progress.get(f"state/{k}", np.nan))
        meta = {"attrs": meta_attrs, "schedule": schedule, "schedule_units": units,
                "progress": [by_name[k] for k in self._progress_fields()]}
        self._build(dest, capacity, meta, data)


@njit(cache=True, nogil=True)
def _scatter(words: np.ndarray, starts: np.ndarray, row: int, block: np.ndarray) -> None:  # pragma: no cover - compiled
    """Column c of `block` (c < len(starts)) into the float64 dataset whose values begin at word starts[c] of the
    mapped file, from its row `row` on (the capacity is made sure of before)."""
    for c in range(starts.shape[0]):
        base = starts[c] + row
        for i in range(block.shape[0]):
            words[base + i] = block[i, c]


@njit(cache=True, nogil=True)
def _scatter_streams(words: np.ndarray, starts: tuple, rows: np.ndarray, blocks: tuple) -> None:  # pragma: no cover - compiled
    """_scatter for several streams in one call: blocks[s] from row rows[s] into the datasets at starts[s]."""
    for s in range(len(blocks)):
        _scatter(words, starts[s], rows[s], blocks[s])


def prime(layout: Layout) -> None:
    """Compile (or load from numba's cache) the kernels a RunWriter of `layout` calls, and its `derive`, before a
    control loop flushes one (a first-call compile there stalls the loop): each once on zero rows, with a scratch
    builder and no file (nothing written)."""
    builder = AlignedBuilder(layout)
    held = tuple(np.zeros((0, 1 + len(spec.columns))) for spec in builder._held)  # noqa: SLF001 - its own module
    grid = np.zeros((0, len(builder.channels)))
    _hold_streams(builder._carries, held, 0, layout.dt, builder._holds, builder._plans, grid)  # noqa: SLF001
    for carry, readings, hold, plan in zip(builder._carries, held, builder._holds, builder._plans):  # noqa: SLF001
        _hold_on_grid(carry, readings, 0, layout.dt, hold, plan, grid)  # readings out of time order: called alone
    _scatter(np.zeros(0), np.zeros(len(layout.aligned_units), np.int64), 0, grid)
    _scatter_streams(np.zeros(0), tuple(np.zeros(1 + len(s.columns), np.int64) for s in layout.streams),
                     np.zeros(len(layout.streams), np.int64),
                     tuple(np.zeros((0, 1 + len(s.columns))) for s in layout.streams))
    if layout.derive is not None:
        layout.derive({channel: np.zeros(0) for channel in builder.channels})


def _tmp(path: Path) -> Path:
    """Where a new version of `path` is built before it replaces it."""
    return path.with_name(path.name + ".tmp")


COMPRESS_FROM = 1024  # values: smaller datasets of the compact file stay contiguous


class _Rows:
    """The first `rows` values of a stored dataset, read a slice at a time: a rebuild copies a run chunk by chunk
    instead of holding it whole (the closing compaction of a long run, issue 47)."""

    def __init__(self, dataset: h5py.Dataset, rows: int) -> None:
        self.dataset, self.rows = dataset, min(int(rows), dataset.shape[0])
        self.dtype, self.shape, self.size = dataset.dtype, (self.rows,), self.rows

    def __len__(self) -> int:
        return self.rows

    def __getitem__(self, part: slice) -> np.ndarray:
        start, stop, _ = part.indices(self.rows)
        return self.dataset[start:max(start, stop)]


COPY_ROWS = 65536  # rows a rebuild of the running file copies at a time


def _capacity_dataset(parent: h5py.Group, name: str, capacity: int, values: "np.ndarray | _Rows | None",
                      grid_dt: float | None) -> h5py.Dataset:
    """A running file's float64 dataset `name`: contiguous, allocated at `capacity` and NaN-filled by HDF5 when
    made, then `values` (the valid rows of the file it replaces) or, with `grid_dt`, the grid's times written in
    slices of COPY_ROWS: never a capacity-sized array in memory (a one-week run's column is 480 MB, issue 47)."""
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)  # its place in the file known, and filled, now
    ds = parent.create_dataset(name, shape=(capacity,), dtype="<f8", fillvalue=np.nan, fill_time="alloc",
                               dcpl=dcpl, track_times=False)
    rows = capacity if grid_dt is not None else min(len(values), capacity) if values is not None else 0
    for start in range(0, rows, COPY_ROWS):
        stop = min(start + COPY_ROWS, rows)
        ds[start:stop] = np.arange(start, stop) * grid_dt if grid_dt is not None else values[start:stop]
    return ds


def _dataset(parent: h5py.Group, name: str, arr: "np.ndarray | _Rows", compact: bool) -> h5py.Dataset:
    """`arr` as dataset `name`: contiguous, or in the compact file (if large enough) chunked, shuffled and gzipped
    (`runfile.compressed`)."""
    if not compact or arr.size < COMPRESS_FROM:
        return parent.create_dataset(name, data=arr[:], track_times=False)
    return compressed_dataset(parent, name, arr)


def describe_layout(layout: Layout) -> dict[str, Any]:
    """A JSON-able description of the layout (stored in /acquire, for people and tools)."""
    return {"dt": layout.dt,
            "streams": [{"name": s.name, "columns": dict(s.columns), "rate_hz": s.rate_hz, "hold_s": s.hold_s}
                        for s in layout.streams],
            "aligned": {src.channel: {"stream": src.stream, "column": src.column, "scale": src.scale}
                        for src in layout.sources},
            "derived": [c for c in layout.aligned_units if c not in {s.channel for s in layout.sources}]}
