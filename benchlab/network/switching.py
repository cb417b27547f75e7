"""A switch with hysteresis over a sampled signal (a thermostat, a fan, a valve): the one law of a model file whose
value at a sample depends on the samples before it, so its state is carried from sample to sample.

`hysteresis(x, off, on)` is 1 while switched on and 0 while off: it switches on where x rises to `on` or above,
off where it falls to `off` or below, and keeps its state in between; it starts off unless the first sample is at
or above `on`. Its value at sample k is its mean over the step from sample k to k + 1 (x linear between the two),
as the solver holds it over that step: a step in which it switches takes the share after (on) or before (off) the
crossing, so the law is continuous in its thresholds, as a fit's finite differences need. `off` above `on` is no
switch, and neither is a
threshold that is not one number (a channel): NaN, which a law's checks refuse.
"""

from __future__ import annotations

import numpy as np

from benchlab.jit import njit


@njit(cache=True, nogil=True)
def _switched(x, off, on, out):  # pragma: no cover - compiled
    """out[k] = the switch's mean over step k (module docstring); NaN samples keep the state."""
    n = x.shape[0]
    if n == 0:
        return
    state = x[0] >= on
    for k in range(n - 1):
        a, b = x[k], x[k + 1]
        if not state and b >= on and a < on:
            out[k] = 1.0 - (on - a) / (b - a)
            state = True
        elif state and b <= off and a > off:
            out[k] = (a - off) / (a - b)
            state = False
        else:
            out[k] = 1.0 if state else 0.0
    out[n - 1] = 1.0 if state else 0.0


def hysteresis(x: "float | np.ndarray", off: "float | np.ndarray", on: "float | np.ndarray") -> np.ndarray:
    """The switch's value per sample of `x` (module docstring); thresholds are scalars (parameters, numbers)."""
    values = np.atleast_1d(np.asarray(x, dtype=np.float64))
    out = np.empty(len(values))
    if np.ndim(off) or np.ndim(on):  # a threshold that moves from sample to sample is no thermostat's
        out[:] = np.nan
        return out
    low, high = float(off), float(on)
    if not low <= high:
        out[:] = np.nan
        return out
    _switched(np.ascontiguousarray(values), low, high, out)
    return out
