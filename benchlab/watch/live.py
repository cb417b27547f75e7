"""What the live page shows, kept up to date from the run file: decimated channels, run state, step, events.

Each update of the page asks for what is new since its last one: the buckets from the last (still filling) one
on, at the level (bucket size) its plot needs, and the events after the last it has. Before answering, the run
file is read for what the writer has added since the previous request (benchlab/runfile/live.py), so one
update costs what arrived plus what is sent, however long the run is.
"""

from __future__ import annotations

import base64
import math
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.errors import InputError
from benchlab.watch.decimate import BASE_LEVEL, TOP_LEVEL, MinMaxPyramid, minmax
from benchlab.runfile.live import RunFileVersion
from protocols.schedule import Step

#: At most this many buckets per answer (the page asks again for the rest), and at most this many grid rows read
#: for buckets finer than the pyramid's, so no single answer grows with the run.
MAX_BUCKETS = 4096
MAX_FINE_ROWS = 1 << 18
#: At most this many events per answer.
MAX_EVENTS = 500
#: Rows read at a time when catching up with a long run (bounds the memory of the first read).
CATCH_UP_ROWS = 1 << 18
STATE_PREFIX = "state/"


def encode(values: np.ndarray) -> str:
    """float32 little-endian bytes in base64: compact, exact for the page, NaN kept."""
    return base64.b64encode(np.ascontiguousarray(values, dtype="<f4").tobytes()).decode("ascii")


class Schedule:
    """The planned steps with what the page needs computed once: expected time after each step, cycles."""

    def __init__(self, steps: Sequence[Step]) -> None:
        self.steps = tuple(steps)
        expected = np.array([s.expected_s for s in self.steps], dtype=float)
        self.after = np.concatenate([np.cumsum(expected[::-1])[::-1][1:], [0.0]]) if len(expected) else expected
        self.planned_s = float(expected.sum())
        self.cycles = len({s.cycle for s in self.steps})

    def status(self, state: Mapping[str, float], last_step_event: tuple[str, float] | None,
               t_data: float) -> dict[str, Any] | None:
        """The step under way and its time left (None without a schedule or before the first step).

        `state` holds the runner's progress fields (next_step: index of the step under way, or of the next
        once one has ended); `last_step_event` the kind and time of the last step_start/step_end event.
        """
        index = state.get("next_step", math.nan)
        if not self.steps or not math.isfinite(index):
            return None
        i = int(index)
        if i >= len(self.steps):
            return {"index": i, "steps": len(self.steps), "done": True, "run_left_s": 0.0}
        step = self.steps[i]
        started = last_step_event is not None and last_step_event[0] == "step_start"
        elapsed = max(0.0, t_data - last_step_event[1]) if started and last_step_event else 0.0
        expected_left = max(0.0, step.expected_s - elapsed)
        return {
            "index": i, "steps": len(self.steps), "done": False, "cycle": step.cycle, "cycles": self.cycles,
            "phase": step.phase, "label": step.label, "engine_speed_rpm": step.engine_speed_rpm,
            "clutch_torque_nm": step.clutch_torque_nm, "load_torque_nm": step.load_torque_nm, "started": started,
            "elapsed_s": elapsed, "left_s": max(0.0, step.duration_s - elapsed), "expected_left_s": expected_left,
            "until": " or ".join(c.describe() for c in step.until) if step.until else
            ("synchronised" if step.phase == "launch" else ""),
            "run_left_s": float(self.after[i]) + expected_left,
        }


def choose_level(span_rows: int, width: int) -> int:
    """The bucket size (2**level rows) that puts `span_rows` on at most `width` buckets, one per pixel."""
    if span_rows <= width or width < 1:
        return 0
    return min(TOP_LEVEL, math.ceil(math.log2(span_rows / width)))


class LiveRun:
    """One watched run file: follows it as it is written and answers the page's updates (thread-safe)."""

    def __init__(self, path: "str | Path") -> None:
        self.path = Path(path)
        self.version = RunFileVersion(self.path)  # InputError: not a run file
        self.generation = 0
        self.problem: str | None = None
        self._lock = threading.Lock()
        self._reset()

    def _reset(self) -> None:
        v = self.version
        self.schedule = Schedule(v.steps)
        self.names = list(v.channels)
        self.pyramid = MinMaxPyramid(len(self.names))
        self.rows = 0
        self.events: list[dict[str, Any]] = []
        self.latest: dict[str, tuple[float, float]] = {}
        self.interlocks: dict[str, str] = {}  # active interlock -> its event's detail
        self.last_step_event: tuple[str, float] | None = None
        self.progress: dict[str, float] = {}
        self.quiet_since = time.monotonic()

    # -- reading ----------------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Read what the writer added since the last call (and follow the file if it was replaced)."""
        if self.version.replaced():
            self._reopen()
        progress = self.version.progress()
        if progress != self.progress:
            self.quiet_since = time.monotonic()
        self.progress = progress
        rows = self.version.valid_rows(progress)
        if rows < self.rows:  # the same run with fewer rows: only another run can do that
            self._start_again("the run file now holds fewer rows: started again")
            rows = self.version.valid_rows(self.progress)
        while self.rows < rows:
            start = self.rows - self.rows % (1 << BASE_LEVEL)  # the base bucket still filling, read whole again
            stop = min(rows, start + CATCH_UP_ROWS)
            block = self.version.read_channels(start, stop)
            self.pyramid.ingest(start, block)
            self._note_latest(start, block)
            self.rows = stop
        n_events = self.version.event_rows(progress)
        if n_events > len(self.events):
            for event in self.version.read_events(len(self.events), n_events):
                self._note_event(event)
                self.events.append(event)

    def _reopen(self) -> None:
        try:
            version = RunFileVersion(self.path)
        except (InputError, OSError) as exc:  # gone, or half-made by another tool: keep showing what was read
            self.problem = f"{self.path.name} cannot be read any more ({exc}): showing what was read"
            return
        old, self.version = self.version, version
        old.close()
        self.problem = None
        if version.identity != old.identity:
            self._start_again(f"{self.path.name} now holds another run: started again")

    def _start_again(self, why: str) -> None:
        self.generation += 1
        self._reset()
        self.progress = self.version.progress()
        self.problem = why

    def _note_latest(self, start: int, block: np.ndarray) -> None:
        finite = np.isfinite(block)
        last = block.shape[1] - 1 - np.argmax(finite[:, ::-1], axis=1)
        for i in np.flatnonzero(finite.any(axis=1)):
            row = start + int(last[i])
            self.latest[self.names[i]] = (float(block[i, last[i]]), self.version.t0 + row * self.version.dt)

    def _note_event(self, event: Mapping[str, Any]) -> None:
        kind = event["kind"]
        if kind in ("step_start", "step_end"):
            self.last_step_event = (kind, event["time"])
        elif kind == "interlock":
            self.interlocks[event["reason"]] = event["detail"]
        elif kind in ("interlock_cleared", "resume"):
            self.interlocks.clear()

    # -- answers ----------------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """The run's state: attributes, rows, bench time, latest values, step under way, interlocks."""
        v, progress = self.version, self.progress
        state = {k[len(STATE_PREFIX):]: val for k, val in progress.items() if k.startswith(STATE_PREFIX)}
        t_data = progress.get("t_data", v.t0 + (self.rows - 1) * v.dt if self.rows else v.t0)
        return {
            "file": self.path.name, "generation": self.generation, "status": v.status,
            "protocol": str(v.attrs.get("protocol", "")), "seed": _json_number(v.attrs.get("seed")),
            "bench": str(v.attrs.get("bench", "")), "created_utc": str(v.attrs.get("created_utc", "")),
            "dt": v.dt, "t0": v.t0, "rows": self.rows, "t_data": _json_number(t_data),
            "planned_s": self.schedule.planned_s,
            "channels": [{"name": n, "unit": v.channels[n]} for n in self.names],
            "latest": {n: {"value": _json_number(val), "time": t} for n, (val, t) in self.latest.items()},
            "state": {k: _json_number(val) for k, val in state.items()},
            "held": state.get("held", 0.0) == 1.0, "interlocks": dict(self.interlocks),
            "step": self.schedule.status(state, self.last_step_event, float(t_data)),
            "events": len(self.events), "quiet_s": time.monotonic() - self.quiet_since,
            "problem": self.problem, "base_level": BASE_LEVEL, "top_level": TOP_LEVEL,
        }

    def series(self, level: int, first: int) -> dict[str, Any]:
        """Min/max of every channel per bucket of 2**level rows, buckets `first`... (at most MAX_BUCKETS)."""
        size = 1 << level
        stop = first + (MAX_BUCKETS if level >= BASE_LEVEL else min(MAX_BUCKETS, max(1, MAX_FINE_ROWS // size)))
        if level >= BASE_LEVEL:
            mins, maxs = self.pyramid.buckets(level, first, stop)
        else:
            mins, maxs = minmax(self.version.read_channels(first * size, min(stop * size, self.rows)), size)
        return {"level": level, "rows_per_bucket": size, "first": first, "count": int(mins.shape[1]),
                "total": -(-self.rows // size), "min": [encode(m) for m in mins], "max": [encode(m) for m in maxs]}

    def update(self, width: int = 1000, span_s: float = 0.0, level: int | None = None, have: int = 0,
               events_from: int | None = None) -> dict[str, Any]:
        """One update of the page: read what is new, then answer with the status, buckets and events.

        The page plots the last `span_s` seconds (0: the whole run) on `width` pixels, holds buckets up to
        (not including) `have` at `level`, and events up to `events_from`. It gets the buckets from its last
        one on (that one may have filled since), or, when the bucket size the span needs has changed (the run
        grew, the span was changed), the span's buckets at the new size. Buckets before the span it drops.
        """
        with self._lock:
            self.refresh()
            answer: dict[str, Any] = {"status": self.status()}
            span_rows = self.rows if span_s <= 0 else min(self.rows, math.ceil(span_s / self.version.dt))
            need = choose_level(span_rows, width)
            start = (self.rows - span_rows) >> need
            first = max(start, have - 1) if need == level and have > 0 else start
            answer["series"] = {**self.series(need, first), "span_first": start}
            if events_from is not None:
                begin = max(0, int(events_from))
                answer["events"] = {"first": begin, "items": self.events[begin:begin + MAX_EVENTS]}
            return answer

    def close(self) -> None:
        with self._lock:
            self.version.close()


def _json_number(value: Any) -> float | None:
    """A number for JSON: NaN and infinities (not valid JSON) become null."""
    if isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(float(value)):
        return float(value)
    return None
