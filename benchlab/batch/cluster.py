"""Where a batch runs: a local dask.distributed cluster on this machine, loopback only, or an existing scheduler.

dask is an optional extra (`pip install -e '.[cluster]'`); without it `benchlab batch` is bad usage (exit 2)
and names the extra. The local cluster's scheduler, workers and dashboard listen on 127.0.0.1 only, on
ports the system picks; one single-threaded worker process per core (the fits are CPU-bound Python and
numba: threads of one process would share one interpreter lock). Its logs are silenced below CRITICAL:
a task's failure comes back as its row, and a heartbeat cut short as the cluster closes is no news.
Its workers start without dask's MALLOC_TRIM_THRESHOLD_=65536: a fixed trim threshold also fixes glibc's
mmap threshold, so every large array of a fit is mapped and unmapped afresh; measured, identify took
1.6x the CPU time and 2x the wall time in such a worker (benchmarks/README.md, bench_batch.py).
"""

from __future__ import annotations

import importlib.util
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from benchlab.errors import InputError

LOOPBACK = "127.0.0.1"
EXTRA = "pip install -e '.[cluster]'"
#: dask config for the local cluster's worker processes: None unsets the variable (see the module's docstring).
WORKER_ENVIRONMENT = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def require_distributed() -> ModuleType:
    """The dask.distributed module, or bad usage naming the optional extra that installs it."""
    try:
        import distributed
    except ImportError:
        raise InputError("dask.distributed", "import", f"installed: it is the optional extra `{EXTRA}`") from None
    return distributed


@dataclass
class Connection:
    """A client and what to tell the user about where it runs."""

    client: Any  # distributed.Client
    scheduler: str
    dashboard: str | None  # None: no dashboard (bokeh not installed)
    workers: int
    local: bool


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


@contextmanager
def connect(scheduler: str | None, workers: int, timeout_s: float) -> Iterator[Connection]:
    """A client of a new local cluster of `workers` processes (scheduler None), or of the scheduler at that address.

    A scheduler that cannot be reached within `timeout_s` is bad input (InputError naming the address).
    """
    distributed = require_distributed()
    if scheduler is None:
        import dask

        with dask.config.set(WORKER_ENVIRONMENT):  # read as the nannies are made, kept for restarts
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=LOOPBACK,
                                               dashboard_address=f"{LOOPBACK}:0", silence_logs=logging.CRITICAL)
        with cluster, distributed.Client(cluster) as client:
            dashboard = client.dashboard_link if importlib.util.find_spec("bokeh") else None
            yield Connection(client, cluster.scheduler_address, dashboard, workers, local=True)
        return
    try:
        client = distributed.Client(scheduler, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise InputError(scheduler, "--scheduler", f"a dask scheduler that answers within {timeout_s:g} s, "
                                                   f"e.g. tcp://HOST:8786 ({_first_line(exc)})") from None
    with client:
        info = client.scheduler_info()
        dashboard = client.dashboard_link if "dashboard" in info.get("services", {}) else None
        yield Connection(client, scheduler, dashboard, len(info.get("workers", {})), local=False)
