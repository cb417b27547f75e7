"""Callendar–Van Dusen (IEC 60751) conversion between platinum RTD resistance and temperature.

The only place in benchlab where a PT1000 resistance becomes a temperature (and back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
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
        return temperature_of(float(resistance_ohm), coef.r0, coef.a, coef.b, coef.c)
    r = np.asarray(resistance_ohm, dtype=float)
    return _like(_temperatures(r.ravel(), coef.r0, coef.a, coef.b, coef.c).reshape(r.shape), resistance_ohm)


@njit(cache=True, nogil=True)
def temperature_of(r: float, r0: float, a: float, b: float, c: float) -> float:  # pragma: no cover - compiled
    """`temperature` of one resistance with the coefficients spelled out (the one implementation of the inverse)."""
    disc = a * a - 4.0 * b * (1.0 - r / r0)
    if r >= r0 or math.isnan(r):
        return (-a + math.sqrt(disc)) / (2.0 * b) if disc >= 0 else math.nan
    t = (-a + math.sqrt(disc)) / (2.0 * b) if disc >= 0 else (r / r0 - 1.0) / a
    for _ in range(_NEWTON_STEPS):
        f = r0 * (1.0 + a * t + b * t * t + c * (t - 100.0) * t * t * t) - r
        t -= f / (r0 * (a + 2.0 * b * t + c * (4.0 * t * t * t - 300.0 * t * t)))
    return t


@njit(cache=True, nogil=True)
def _temperatures(r: np.ndarray, r0: float, a: float, b: float, c: float) -> np.ndarray:  # pragma: no cover - compiled
    """`temperature_of` for each of `r`."""
    out = np.empty(r.shape[0])
    for i in range(r.shape[0]):
        out[i] = temperature_of(r[i], r0, a, b, c)
    return out


def in_range(temperature_c: ArrayLike) -> np.ndarray | bool:
    """True where the temperature lies in the IEC 60751 validity range −200…850 °C."""
    if isinstance(temperature_c, float):  # one reading (the drivers): no numpy round trip
        return T_MIN_C <= temperature_c <= T_MAX_C
    t = np.asarray(temperature_c, dtype=float)
    return _like((t >= T_MIN_C) & (t <= T_MAX_C), temperature_c)


def _like(result: np.ndarray, arg: ArrayLike) -> np.ndarray | float | bool:
    """Return a Python scalar for a scalar argument, the array otherwise."""
    return result.item() if np.ndim(arg) == 0 else result


def prime() -> None:
    """Compile (or load from numba's cache) the conversions a bench's loop calls (one value, an array), before it
    runs: a first-call compile inside a control loop stalls it."""
    temperature(PT1000.r0)
    temperature(np.zeros(0))
