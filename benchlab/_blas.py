"""Single-threaded BLAS for benchlab's numeric work, whatever the caller imported first or set.

benchlab's matrices are small (4-7 states, Jacobians of a dozen columns): BLAS threads only cost. Two layers:
the thread variables are defaulted to 1 when this module loads, so a BLAS loaded afterwards starts without
worker threads (a tiny expm took 15 ms threaded, 0.01 ms not); and `single_threaded_blas` limits every BLAS
already loaded for the duration of a fit, whatever was imported first and whatever the variables say
(numpy imported before benchlab, or OPENBLAS_NUM_THREADS set or empty, gave a 2 h identification 5x the
CPU). The caller's own limits are restored afterwards. Nested and concurrent uses share one limit.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, ParamSpec, TypeVar

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

P = ParamSpec("P")
R = TypeVar("R")

_lock = threading.Lock()
_depth = 0
_limiter: Any = None


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Every loaded BLAS runs one thread inside the block; the outermost block restores what was there."""
    global _depth, _limiter
    with _lock:
        if _depth == 0:
            from threadpoolctl import threadpool_limits  # here: `import benchlab` stays light

            _limiter = threadpool_limits(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _limiter.restore_original_limits()
                _limiter = None


def single_threaded_blas(func: Callable[P, R]) -> Callable[P, R]:
    """Decorator: `func` runs inside `one_blas_thread()` (entry points of the fits and analyses)."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with one_blas_thread():
            return func(*args, **kwargs)

    return wrapper
