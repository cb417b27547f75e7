"""Which fitted parameters the runs do not pin down, and why: the one home of "not identified by these runs".

A parameter is not identified when the fit put it on a bound (the data pushed it as far as it was allowed to go),
when its standard error is zero or not finite (the measured channels do not depend on it), when its standard error
exceeds its value (the data are compatible with zero and with twice the value), or when independent starts that
reached the same cost put it far apart (the cost is flat along it). The standard error of such a parameter says
nothing and is not shown as if it did (`benchlab identify`, the report, the pages). Each reason says what would
identify it, read from the model file (benchlab.identify.excitation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from benchlab.identify.excitation import what_identifies
from benchlab.identify.spec import ParamSpec
from benchlab.model.build import build_spec
from benchlab.values import finite_number

if TYPE_CHECKING:
    from benchlab.identify.fit import FitResult
    from benchlab.model.definition import ModelDefinition
    from benchlab.model.params import ModelParams

#: A value within this fraction of its bound's distance (in the fitted coordinate: log for positive parameters)
#: counts as on the bound.
BOUND_TOLERANCE = 1e-3
#: Two starts reached the same cost when their costs differ by less than this many residual variances: the 95 %
#: point of chi-squared with one degree of freedom, the rise of the cost that bounds one parameter's
#: profile-likelihood interval. Within it the data prefer neither start. (The residual variance of white residuals:
#: on autocorrelated ones the true interval is wider, so this errs towards calling a parameter identified.)
SAME_COST_CHI2 = 3.84
#: Starts at the same cost put a parameter far apart when their values differ by more than the value itself, or,
#: for a positive parameter, by more than this factor: the data then allow zero or twice the value, as a standard
#: error above the value says.
FAR_APART_FACTOR = 2.0
#: A standard error below this share of its value is rounding, not information: the covariance of a parameter whose
#: Jacobian column is zero comes out of the pseudo-inverse as 1e-17-ish instead of 0 (a switch's band that the runs
#: never cross: 1.9e-17 K on 9.55 K); no run of kelvin-level noise pins a parameter to a part in 10^12.
ZERO_ERROR_SHARE = 1e-12


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


def starts_at_the_minimum(result: "FitResult") -> list[dict[str, float]]:
    """The parameters of the multistart's starts whose cost on the runs is within SAME_COST_CHI2 residual variances of
    the lowest start's (benchlab.identify.fit.fit_multistart keeps each start's end)."""
    if not result.start_costs:
        return []
    variance = result.cost / max(result.n_residuals - len(result.free_names), 1)
    lowest = min(result.start_costs)
    return [dict(params) for cost, params in zip(result.start_costs, result.start_params)
            if cost - lowest <= SAME_COST_CHI2 * variance]


def _far_apart(spec: ParamSpec, value: float, others: Sequence[float]) -> tuple[float, float] | None:
    """The lowest and highest of `value` and `others` where they lie FAR_APART_FACTOR or more apart, else None."""
    found = [value, *others]
    low, high = min(found), max(found)
    if spec.log and low > 0:
        return (low, high) if high / low > FAR_APART_FACTOR else None
    return (low, high) if high - low > abs(value) else None


def _why(spec: ParamSpec, value: float, error: float | None, others: Sequence[float]) -> str | None:
    """Why one parameter is not identified (None where it is)."""
    side = on_bound(spec, value)
    if side is not None:
        limit = spec.lower if side == "lower" else spec.upper
        return (f"on its {side} bound ({value:.4g}, bound {limit:.4g}): the runs push it as far as the model file "
                "allows")
    if error is not None and (not np.isfinite(error) or error <= ZERO_ERROR_SHARE * abs(value)):
        return "the measured channels do not depend on it (no standard error)"
    if error is not None and error > abs(value):
        return f"standard error {error:.3g} exceeds its value {value:.4g}"
    spread = _far_apart(spec, value, others)
    if spread is not None:
        return (f"starts that reached the same cost put it anywhere from {spread[0]:.4g} to {spread[1]:.4g} (the "
                "cost is flat along it)")
    return None


def not_identified(specs: Sequence[ParamSpec], values: Mapping[str, float], errors: Mapping[str, float],
                   starts: Sequence[Mapping[str, float]] = (),
                   model: "ModelDefinition | None" = None) -> dict[str, str]:
    """Parameter -> why the runs do not identify it (on a bound; no effect; standard error above its value; starts
    at the same cost far apart: `starts`, as `starts_at_the_minimum` gives them) and, with the `model`, what would
    identify it (benchlab.identify.excitation)."""
    reasons: dict[str, str] = {}
    for spec in specs:
        value = values.get(spec.name)
        if value is None:
            continue
        why = _why(spec, value, errors.get(spec.name), [s[spec.name] for s in starts if spec.name in s])
        if why is None:
            continue
        needs = what_identifies(model, spec.name.split("@")[0]) if model is not None else ""  # X@group: X's law
        reasons[spec.name] = f"{why}; would be identified by {needs}" if needs else why
    return reasons


def not_identified_lines(reasons: Mapping[str, str]) -> list[str]:
    """The warnings that lead `benchlab identify`'s list: one line per parameter the runs do not identify."""
    return [f"{name} is not identified by these runs: {why}" for name, why in reasons.items()]


def recorded(params: "ModelParams") -> dict[str, str]:
    """A parameter file's not-identified parameters with their reasons: its "not_identified" object, or, in a file
    written before it existed, what its standard errors and its model's bounds say (`not_identified`)."""
    found = params.extra.get("not_identified")
    if isinstance(found, dict):
        return {str(k): str(v) for k, v in found.items() if k in params}
    errors = params.extra.get("uncertainty")
    if not isinstance(errors, dict):
        return {}
    numbers = {k: finite_number(v) for k, v in errors.items()}
    return not_identified(build_spec(params.definition).free, params,
                          {k: v if v is not None else float("nan") for k, v in numbers.items()},
                          model=params.definition)
