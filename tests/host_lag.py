"""How long the host kept a real-time test's threads waiting for a core, and the verdict that follows from it.

A real-time test runs its devices on the wall clock: on a loaded host (a shared CI machine, other sessions) the
emulators' threads and the loop wait for a core for whole seconds, and a launch then does not reach its speed in the
step's time. That says nothing about the code under test. `HostLag` reads the kernel's own account of it: each
thread's run delay (`/proc/self/task/TID/schedstat`, the time it was ready to run and the scheduler ran something
else), sampled while the test runs. A thread waiting on the GIL or on I/O is not ready to run, so a stall of the
code's own making (a compile in the loop, a blocking call) is not counted and still fails. `judged` keeps every
assertion as it is and, only where one fails while some thread waited longer than the check can absorb, skips with
the measured wait as its reason. On a host that kept real time a failure fails; without schedstat (not Linux, or a
kernel without it) nothing is skipped.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

TASKS = Path("/proc/self/task")


def _run_delays() -> dict[str, int]:
    """Each thread of this process: its run delay so far in ns (schedstat's second field)."""
    delays = {}
    for task in TASKS.iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):
            delays[task.name] = int((task / "schedstat").read_text().split()[1])
    return delays


class HostLag(contextlib.AbstractContextManager):
    """`with HostLag() as lag:` around a real-time run; afterwards `lag.waited_s` is the longest time one thread of
    the process was ready to run and kept waiting for a core (None where the kernel does not say)."""

    def __init__(self, period_s: float = 0.02) -> None:
        self.period_s, self.waited_s = period_s, None
        self._first: dict[str, int] = {}
        self._last: dict[str, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, name="host-lag", daemon=True)

    def _note(self) -> None:
        for tid, delay in _run_delays().items():
            self._first.setdefault(tid, delay)
            self._last[tid] = delay

    def _sample(self) -> None:
        while not self._stop.wait(self.period_s):
            self._note()

    def __enter__(self) -> HostLag:
        if (TASKS / str(os.getpid()) / "schedstat").exists():
            self._note()
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._thread.is_alive():
            self._stop.set()
            self._thread.join()
            self._note()
            self.waited_s = max((self._last[t] - self._first[t] for t in self._last), default=0) / 1e9

    @contextlib.contextmanager
    def judged(self, tolerable_s: float) -> Iterator[None]:
        """The assertions inside as they are; one failing while a thread waited for a core longer than
        `tolerable_s` (the slack the check has: a step's margin, the frames a poll may miss) is a skip naming the
        wait, not a failure."""
        try:
            yield
        except AssertionError as exc:
            if self.waited_s is None or self.waited_s <= tolerable_s:
                raise
            said = str(exc).splitlines()[0] if str(exc) else "failed"
            pytest.skip(f"the host did not keep real time: a thread of the run waited {self.waited_s:.2f} s for a "
                        f"core, the check absorbs {tolerable_s:.2f} s (its assertion: {said})")
