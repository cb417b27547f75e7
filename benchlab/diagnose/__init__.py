"""Show what the model gets wrong, name the cause, extend the model, measure the gain.

`diagnose` loads on first use, so `benchlab.diagnose.parallel` (the command line's `--workers` default) costs no
scipy.
"""

import typing as _typing

from benchlab._lazy import lazy_exports as _lazy_exports

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports it on first use
    from benchlab.diagnose.report import diagnose

__all__ = ["diagnose"]
__getattr__, __dir__ = _lazy_exports(__name__, {".report": ("diagnose",)})
