"""Independent candidate fits on every core the process may use, or serially where it may not fork.

Fork-based: a worker inherits the networks, whose laws are closures that cannot be pickled, so
only an index goes out and plain numbers and arrays come back. No pool is started inside a
daemonic process (multiprocessing forbids it children: a Dask worker process is one) nor inside
a Dask worker thread (forking a process whose other threads hold locks can hang the child); there
the fits run one after another in the caller's thread: `benchlab batch` already keeps every worker
busy with one run each, and the closures could not be shipped to the worker's other threads anyway.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

_task: Callable[[int], object] | None = None


def _run(index: int) -> object:
    return _task(index)


def _worker_start() -> None:
    """A forked worker dies by SIGTERM, as the pool ends it: the command's own answer to SIGTERM (benchlab.interrupts
    `terminate_as_interrupt`, inherited through fork) would raise in every worker the pool closes and print its
    traceback. Then it gives back the free heap it shares with its parent (`release_free_heap`)."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    release_free_heap()


def release_free_heap() -> None:
    """glibc's malloc_trim(0): the heap's free pages handed back to the kernel. In a forked worker they are the
    parent's, shared copy-on-write: every fit's arrays reuse them, and each first write copied a 4 KiB page the fit
    then overwrote. Handed back, they come as fresh zero pages. Diagnose on the main job's runs, two workers, seven
    runs alternated with seven without: minor faults 360-400 k -> 320-340 k (one outlier each, 595 k and 587 k),
    CPU median 23.7 -> 23.5 s (paired differences -0.9..+0.1 s; serially, in one process: 22.5-22.8 s). Nothing
    where the C library has no malloc_trim (not glibc)."""
    trim = getattr(ctypes.CDLL(None), "malloc_trim", None)
    if trim is not None:
        trim(0)


def workers() -> int:
    """Cores this process may run on (CI: 2)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def in_dask_worker() -> bool:
    """Whether this thread runs a task of a dask.distributed worker (only asked when distributed is loaded)."""
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return False
    try:
        distributed.get_worker()
    except ValueError:  # "No worker found": not a worker's task thread
        return False
    return True


def may_fork() -> bool:
    """Whether a pool of forked processes may be started here: fork exists, not a daemon, not a Dask worker."""
    return ("fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon
            and not in_dask_worker())


TASKS_PER_WORKER = 8  # chunks a worker takes of a long map: few enough round trips, small enough to balance


def chunk_size(count: int, n: int) -> int:
    """Tasks a worker takes at a time: one where there are few (each fit is long; one per round trip balances best),
    a TASKS_PER_WORKER-th of its share of a long map of short tasks (the score test's 336 candidates of ~7 ms: one
    per round trip cost 0.4-0.5 s CPU of pickling and waking per map, in parent and worker)."""
    return max(1, count // (n * TASKS_PER_WORKER))


def map_indices(task: Callable[[int], T], count: int, done: Callable[[], None] = lambda: None) -> list[T]:
    """[task(0), …, task(count - 1)], spread over forked workers where there is more than one core and task
    and forking is allowed (may_fork), else in this thread.

    `done` is called in this process as each result comes back (progress).
    """
    global _task
    n = min(count, workers())
    results: list[T] = []
    if n <= 1 or not may_fork():
        for i in range(count):
            results.append(task(i))
            done()
        return results
    _task = task
    try:
        with multiprocessing.get_context("fork").Pool(n, initializer=_worker_start) as pool:
            for result in pool.imap(_run, range(count), chunksize=chunk_size(count, n)):
                results.append(result)
                done()
        return results
    finally:
        _task = None
