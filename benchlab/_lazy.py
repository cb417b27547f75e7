"""Names a package exports that load their module on first use (PEP 562), so importing the package stays light.

One home for the pattern: benchlab, benchlab.runfile, benchlab.diagnose and benchlab.wear export this way, so
that `benchlab.runfile.schema` or the command line's parser (`benchlab --help`) pay for no pandas, h5py or scipy.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any


def lazy_exports(package: str, homes: dict[str, tuple[str, ...]]) -> tuple[Callable[[str], Any],
                                                                            Callable[[], list[str]]]:
    """The package's `__getattr__` and `__dir__` for `homes` (module, relative to the package as `.name`, -> the
    names it exports); a name is imported from its module on first use and then kept in the package."""
    namespace = sys.modules[package].__dict__
    module_of = {name: module for module, names in homes.items() for name in names}

    def __getattr__(name: str) -> Any:
        if name not in module_of:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module_of[name], package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(module_of))

    return __getattr__, __dir__
