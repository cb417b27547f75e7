"""Characteristic maps: 1-D tables with linear interpolation, clamped at the edges."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from benchlab.errors import InputError
from benchlab.values import finite_number


@dataclass(frozen=True)
class Map1D:
    """A table y(x) with a strictly increasing axis; outside the axis the edge value holds."""

    x: np.ndarray
    y: np.ndarray

    def __call__(self, value: "float | np.ndarray") -> "float | np.ndarray":
        """Linear interpolation between table points, clamped at the first and last point."""
        out = np.interp(value, self.x, self.y)
        return float(out) if np.ndim(out) == 0 else out

    def as_lists(self) -> tuple[list[float], list[float]]:
        """Axis and values as plain lists (for TOML/JSON and scalar control-unit code)."""
        return [float(v) for v in self.x], [float(v) for v in self.y]


def make_map(source: str, field: str, axis_name: str, value_name: str, axis: object, values: object,
             minimum: float | None = None) -> Map1D:
    """Check a table read from a file and build it; InputError names `field.axis_name` or `field.value_name`."""
    x = _numbers(source, f"{field}.{axis_name}", axis)
    y = _numbers(source, f"{field}.{value_name}", values)
    if len(x) < 2:
        raise InputError(source, f"{field}.{axis_name}", f"at least two points, got {len(x)}")
    if len(y) != len(x):
        raise InputError(source, f"{field}.{value_name}", f"{len(x)} values like {axis_name}, got {len(y)}")
    if any(b <= a for a, b in zip(x, x[1:])):
        raise InputError(source, f"{field}.{axis_name}", f"strictly increasing values, got {x}")
    if minimum is not None and min(y) < minimum:
        raise InputError(source, f"{field}.{value_name}", f"values >= {minimum}, got {y}")
    return Map1D(np.array(x), np.array(y))


def _numbers(source: str, field: str, values: object) -> list[float]:
    if not isinstance(values, Sequence) or isinstance(values, str):
        raise InputError(source, field, f"a list of numbers, got {values!r}")
    out = []
    for v in values:
        if finite_number(v) is None:
            raise InputError(source, field, f"a list of finite numbers, got {v!r} in it")
        out.append(float(v))
    return out
