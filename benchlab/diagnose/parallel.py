"""Independent candidate fits on every core the process may use.

Fork-based: a worker inherits the networks, whose laws are closures that cannot be pickled, so
only an index goes out and plain numbers and arrays come back.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

_task: Callable[[int], object] | None = None


def _run(index: int) -> object:
    return _task(index)


def workers() -> int:
    """Cores this process may run on (CI: 2)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def map_indices(task: Callable[[int], T], count: int, done: Callable[[], None] = lambda: None) -> list[T]:
    """[task(0), …, task(count - 1)], spread over forked workers where there is more than one core and task.

    `done` is called in this process as each result comes back (progress).
    """
    global _task
    n = min(count, workers())
    results: list[T] = []
    if n <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        for i in range(count):
            results.append(task(i))
            done()
        return results
    _task = task
    try:
        with multiprocessing.get_context("fork").Pool(n) as pool:
            for result in pool.imap(_run, range(count), chunksize=1):
                results.append(result)
                done()
        return results
    finally:
        _task = None
