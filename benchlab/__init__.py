"""benchlab: dry-clutch test-bench acquisition and grey-box thermal modelling (contract section 4).

The API below loads on first use, so `import benchlab.errors` (and the drivers' users) do not pay for
pandas, h5py and numba. `benchlab._blas` comes first: it defaults the BLAS thread variables to 1 before
anything loads numpy (see there for the limit applied during every fit).
"""

import importlib as _importlib
import typing as _typing

from benchlab import _blas  # noqa: F401 - first: thread variables before numpy loads

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports them on first use
    from benchlab.params import load_params
    from benchlab.runfile import load_run
    from benchlab.simulation import simulate

__all__ = ["load_run", "load_params", "simulate"]
__version__ = "0.1.0"

_HOMES = {"load_run": "benchlab.runfile", "load_params": "benchlab.params", "simulate": "benchlab.simulation"}


def __getattr__(name: str) -> _typing.Any:
    """`benchlab.load_run` and the rest of `__all__`, imported from their modules on first use."""
    if name not in _HOMES:
        raise AttributeError(f"module 'benchlab' has no attribute {name!r}")
    value = getattr(_importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
