"""Which fitted parameters the runs do not pin down, and why: the one home of "not identified by these runs".

A parameter is not identified when the fit put it on a bound (the data pushed it as far as it was allowed to go),
when its standard error exceeds its value (the data are compatible with zero and with twice the value), or when
independent starts that reached the same cost put it far apart (the cost is flat along it). The standard error of
such a parameter says nothing and is not shown as if it did (`benchlab identify`, the report, the pages).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from benchlab.identify.spec import ParamSpec

#: A value within this fraction of its bound's distance (in the fitted coordinate: log for positive parameters)
#: counts as on the bound.
BOUND_TOLERANCE = 1e-3


def _coordinate(spec: ParamSpec, value: float) -> float:
    """The fitted coordinate of a value (log for positive parameters), for distances to the bounds."""
    return float(np.log(value)) if spec.log and value > 0 else value / spec.linear_scale


def on_bound(spec: ParamSpec, value: float) -> str | None:
    """'lower' or 'upper' where the value sits on that bound of the search, else None."""
    lo, hi = _coordinate(spec, spec.lower), _coordinate(spec, spec.upper)
    x, width = _coordinate(spec, value), max(_coordinate(spec, spec.upper) - _coordinate(spec, spec.lower), 1e-12)
    if x - lo <= BOUND_TOLERANCE * width:
        return "lower"
    if hi - x <= BOUND_TOLERANCE * width:
        return "upper"
    return None


def not_identified(specs: Sequence[ParamSpec], values: Mapping[str, float],
                   errors: Mapping[str, float]) -> dict[str, str]:
    """Parameter -> why the runs do not identify it (on a bound; standard error above its value; no effect)."""
    reasons: dict[str, str] = {}
    for spec in specs:
        value, error = values.get(spec.name), errors.get(spec.name)
        if value is None:
            continue
        side = on_bound(spec, value)
        if side is not None:
            reasons[spec.name] = f"on its {side} bound ({value:.4g})"
        elif error is not None and (not np.isfinite(error) or error == 0.0 or error > abs(value)):
            reasons[spec.name] = (f"standard error {error:.3g} exceeds its value {value:.4g}" if np.isfinite(error)
                                  and error > 0 else "the measured channels do not depend on it (no standard error)")
    return reasons
