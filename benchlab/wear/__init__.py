"""Wear prediction from the estimated lining temperatures (paper section III.A, eq. 1-3).

The names below load their module on first use, so `benchlab.wear.defaults` (the command line's defaults) costs
no pandas or scipy.
"""

import typing as _typing

from benchlab._lazy import lazy_exports as _lazy_exports

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports them on first use
    from benchlab.wear.analysis import WearReport, analyse_wear
    from benchlab.wear.clutchfile import ClutchSpec, default_clutch, load_clutch
    from benchlab.wear.state import WearState

_HOMES = {"analysis": ("WearReport", "analyse_wear"), "clutchfile": ("ClutchSpec", "default_clutch", "load_clutch"),
          "state": ("WearState",)}
__all__ = sorted(name for names in _HOMES.values() for name in names)
__getattr__, __dir__ = _lazy_exports(__name__, {f".{module}": names for module, names in _HOMES.items()})
