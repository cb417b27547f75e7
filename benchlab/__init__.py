"""benchlab: dry-clutch test-bench acquisition and grey-box thermal modelling (contract section 4).

The API below loads on first use, so `import benchlab.errors` (and the drivers' users) do not pay for
pandas, h5py and numba. `benchlab._blas` comes first: it defaults the BLAS thread variables to 1 before
anything loads numpy (see there for the limit applied during every fit).
"""

import typing as _typing

from benchlab import _blas  # noqa: F401 - first: thread variables before numpy loads
from benchlab._lazy import lazy_exports as _lazy_exports

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports them on first use
    from benchlab.model.params import load_params
    from benchlab.runfile import load_run
    from benchlab.network.simulation import simulate

__all__ = ["load_run", "load_params", "simulate"]
__version__ = "0.1.0"

__getattr__, __dir__ = _lazy_exports(__name__, {".runfile": ("load_run",), ".model.params": ("load_params",),
                                                ".network.simulation": ("simulate",)})
