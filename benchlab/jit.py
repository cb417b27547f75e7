"""numba's `njit` with its on-disk cache made best-effort: every compiled function of benchlab and the simulated
bench is built through here.

numba writes a compiled function's cache file the first time it runs (`cache=True`) and lets any OSError of that
write escape into the caller: on a full disk or a read-only install, `benchlab identify` died on a cache file,
before and regardless of its own output (found by tests/test_disk_full.py on a cold cache). A cache that cannot be
written only costs the next start its compile time, so the write's failure is logged and the command goes on.
"""

from __future__ import annotations

import logging

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
