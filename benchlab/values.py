"""Fields read from user files (TOML, JSON): what counts as a finite number, which keys a table may hold.

TOML and JSON integers have any size, and `math.isfinite` raises OverflowError on one beyond a float's range,
so every check of a number from a file goes through `finite_number` (bools are not numbers either). A table
whose keys are fixed goes through `check_keys`, so a misspelt key is refused rather than left at its default.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping

from benchlab.errors import InputError


def finite_number(value: object) -> float | None:
    """`value` as a finite float, or None if it is not one (a bool, a string, NaN, ±inf, an int beyond a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def positive_number(value: object) -> float | None:
    """`value` as a finite float > 0, or None if it is not one."""
    number = finite_number(value)
    return number if number is not None and number > 0 else None


def check_keys(source: "str | os.PathLike[str]", prefix: str, table: Mapping[str, object], known: Iterable[str]
               ) -> None:
    """InputError on the first key of `table` not in `known`, naming it as `prefix.key` (`key` for an empty
    prefix) and listing the known keys."""
    known = tuple(known)
    for key in table:
        if key not in known:
            raise InputError(source, f"{prefix}.{key}" if prefix else key, f"one of {', '.join(known)} (unknown key)")


def json_ready(value: object) -> object:
    """`value` (nested dicts and lists) with NaN and infinities as None: JSON has no such numbers, null says "none"."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_ready(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
