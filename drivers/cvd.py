"""Callendar–Van Dusen (IEC 60751) conversion between platinum RTD resistance and temperature.

The only place in benchlab where a PT1000 resistance becomes a temperature (and back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

T_MIN_C = -200.0
T_MAX_C = 850.0
_NEWTON_STEPS = 8


@dataclass(frozen=True, slots=True)
class CvdCoefficients:
    """R(T) = R0·(1 + A·T + B·T² + C·(T − 100)·T³), the C term only below 0 °C; defaults are IEC 60751 PT1000."""

    r0: float = 1000.0
    a: float = 3.9083e-3
    b: float = -5.775e-7
    c: float = -4.183e-12


PT1000 = CvdCoefficients()


def resistance(temperature_c: ArrayLike, coef: CvdCoefficients = PT1000) -> np.ndarray | float:
    """Resistance in Ω of the sensor at `temperature_c` (scalar or array, °C)."""
    t = np.asarray(temperature_c, dtype=float)
    r = 1.0 + coef.a * t + coef.b * t * t + np.where(t < 0.0, coef.c * (t - 100.0) * t**3, 0.0)
    return _like(coef.r0 * r, temperature_c)


def temperature(resistance_ohm: ArrayLike, coef: CvdCoefficients = PT1000) -> np.ndarray | float:
    """Temperature in °C for `resistance_ohm`: exact quadratic root at/above R0, Newton on the full equation below."""
    if isinstance(resistance_ohm, (int, float)):
        return _temperature_scalar(float(resistance_ohm), coef)
    r = np.asarray(resistance_ohm, dtype=float)
    with np.errstate(invalid="ignore"):
        t = (-coef.a + np.sqrt(coef.a**2 - 4.0 * coef.b * (1.0 - r / coef.r0))) / (2.0 * coef.b)
    below = r < coef.r0
    if np.any(below):
        tb = np.where(below, np.nan_to_num(t, nan=(r / coef.r0 - 1.0) / coef.a), 0.0)
        rb = np.where(below, r, coef.r0)
        for _ in range(_NEWTON_STEPS):
            f = coef.r0 * (1.0 + coef.a * tb + coef.b * tb**2 + coef.c * (tb - 100.0) * tb**3) - rb
            df = coef.r0 * (coef.a + 2.0 * coef.b * tb + coef.c * (4.0 * tb**3 - 300.0 * tb**2))
            tb = tb - f / df
        t = np.where(below, tb, t)
    return _like(t, resistance_ohm)


def _temperature_scalar(r: float, coef: CvdCoefficients) -> float:
    """`temperature` for one float without numpy overhead (drivers convert one reading at a time)."""
    disc = coef.a**2 - 4.0 * coef.b * (1.0 - r / coef.r0)
    if r >= coef.r0 or math.isnan(r):
        return (-coef.a + math.sqrt(disc)) / (2.0 * coef.b) if disc >= 0 else math.nan
    t = (-coef.a + math.sqrt(disc)) / (2.0 * coef.b) if disc >= 0 else (r / coef.r0 - 1.0) / coef.a
    for _ in range(_NEWTON_STEPS):
        f = coef.r0 * (1.0 + coef.a * t + coef.b * t * t + coef.c * (t - 100.0) * t**3) - r
        t -= f / (coef.r0 * (coef.a + 2.0 * coef.b * t + coef.c * (4.0 * t**3 - 300.0 * t * t)))
    return t


def in_range(temperature_c: ArrayLike) -> np.ndarray | bool:
    """True where the temperature lies in the IEC 60751 validity range −200…850 °C."""
    if isinstance(temperature_c, float):  # one reading (the drivers): no numpy round trip
        return T_MIN_C <= temperature_c <= T_MAX_C
    t = np.asarray(temperature_c, dtype=float)
    return _like((t >= T_MIN_C) & (t <= T_MAX_C), temperature_c)


def _like(result: np.ndarray, arg: ArrayLike) -> np.ndarray | float | bool:
    """Return a Python scalar for a scalar argument, the array otherwise."""
    return result.item() if np.ndim(arg) == 0 else result
