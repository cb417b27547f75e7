"""numba's `njit` with its on-disk cache made best-effort: every compiled function of benchlab and the simulated
bench is built through here.

numba writes a compiled function's cache file the first time it runs (`cache=True`) and lets any OSError of that
write escape into the caller: on a full disk or a read-only install, `benchlab identify` died on a cache file,
before and regardless of its own output (found by tests/test_disk_full.py on a cold cache). A cache that cannot be
written only costs the next start its compile time, so the write's failure is logged and the command goes on.

numba's first compile or cache load in a process imports its every registry, and with them checks that a BLAS is
there by importing `scipy.linalg.cython_blas`, which runs the whole `scipy.linalg` package first (0.2 s CPU, most
of a command that only simulates: scipy's array-API layer, docstrings parsed). The extension module itself needs
none of it, so it is loaded here on its own (`blas_without_scipy_linalg`, 4 ms): numba finds it in place and its
BLAS kernels call it as before; `import scipy.linalg` later runs the package, which takes the module as its own.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import logging
import sys

from numba import njit
from numba.core.caching import Cache

__all__ = ["njit"]

_log = logging.getLogger(__name__)
_save_overload = Cache.save_overload


def _save_overload_or_log(self: Cache, sig: object, data: object) -> None:
    """Cache.save_overload, its OSError logged (the compiled function is in memory and runs) instead of raised."""
    try:
        _save_overload(self, sig, data)
    except OSError as exc:
        _log.info("numba's cache of %s not written (%s): the next start compiles it again", self._name, exc)


Cache.save_overload = _save_overload_or_log

#: the module numba imports to check for a BLAS and calls its kernels' BLAS through
_CYTHON_BLAS = "scipy.linalg.cython_blas"


class _BackToItsPackage(importlib.abc.MetaPathFinder):
    """When `scipy.linalg` is imported, the `cython_blas` loaded on its own leaves `sys.modules`, so the package
    imports it again as its own submodule (Python hands back the same extension module, now also the package's
    attribute), as if it had never been loaded alone; then this finder goes."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name == "scipy.linalg":
            sys.meta_path.remove(self)
            sys.modules.pop(_CYTHON_BLAS, None)
        return None


def blas_without_scipy_linalg() -> None:
    """scipy's `cython_blas` extension loaded without running the `scipy.linalg` package, where neither is loaded
    yet (nothing done without scipy: numba then reports no BLAS as it would have)."""
    if _CYTHON_BLAS in sys.modules or "scipy.linalg" in sys.modules:
        return
    try:
        import scipy
    except ImportError:
        return
    spec = importlib.machinery.PathFinder.find_spec(_CYTHON_BLAS, [f"{scipy.__path__[0]}/linalg"])
    if spec is None or spec.loader is None:
        return
    module = importlib.util.module_from_spec(spec)
    sys.modules[_CYTHON_BLAS] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[_CYTHON_BLAS]
        raise
    sys.meta_path.insert(0, _BackToItsPackage())


blas_without_scipy_linalg()
