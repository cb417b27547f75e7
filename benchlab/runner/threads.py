"""Keep OpenBLAS single-threaded: the solver's tiny matrix exponentials are 1000x slower with thread contention.

On a loaded 2-core machine, scipy.linalg.expm of a 6x6 matrix took 15 ms with OpenBLAS threads and 0.01 ms
without. Setting OPENBLAS_NUM_THREADS only works before numpy loads, so this calls the loaded libraries'
`*openblas_set_num_threads*` through ctypes.
"""

from __future__ import annotations

import ctypes

_SYMBOLS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads64_",
            "openblas_set_num_threads")


def limit_blas_threads(n: int = 1) -> int:
    """Set every loaded OpenBLAS to `n` threads; returns how many libraries were set."""
    import numpy  # noqa: F401 - load the libraries first
    import scipy.linalg  # noqa: F401

    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line}
    except OSError:
        return 0
    done = 0
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _SYMBOLS:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(ctypes.c_int(n))
                done += 1
                break
    return done
