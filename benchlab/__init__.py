"""benchlab: dry-clutch test-bench acquisition and grey-box thermal modelling (contract section 4)."""

import os

# Single-threaded BLAS, set before numpy loads (here, since `benchlab` and the `benchlab` command both pass through
# this file first): threaded OpenBLAS on a busy 2-core machine took 15 ms for a tiny matrix exponential, 0.01 ms
# without threads. setdefault: a value the user set wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Where numpy was imported before benchlab, the variables come too late: limit the loaded BLAS itself.
# Threaded BLAS in diagnose's forked workers made two 30-minute runs take 20 s instead of 7 s.
if os.environ["OPENBLAS_NUM_THREADS"] == "1":
    from threadpoolctl import threadpool_limits  # noqa: E402

    threadpool_limits(limits=1, user_api="blas")

__all__ = ["load_run", "load_params", "simulate"]
__version__ = "0.1.0"

# The API (contract section 4) is imported when first used, not here: the `benchlab` command passes through
# this file first, and importing numpy, pandas and numba here took 1.4 s during which Ctrl-C could not be
# answered cleanly (the command catches it only once benchlab.cli.main runs).
_API = {"load_run": "benchlab.runfile", "load_params": "benchlab.params", "simulate": "benchlab.simulation"}


def __getattr__(name: str) -> object:
    """`benchlab.load_run`, `benchlab.load_params`, `benchlab.simulate`, imported on first use."""
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'benchlab' has no attribute {name!r}")
