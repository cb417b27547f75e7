"""Model-form spread of the states no sensor reads: what the identification leaves open, carried into the band.

The Kalman band of a state no sensor reads (the pressure plate) is conditional on the parameter file being the
plant: it holds the noise, not the model's doubt. The identification states that doubt itself: a covariance of
the fitted parameters (`uncertainty` and `correlation` in the parameter file) and the parameters the runs do not
identify (`benchlab.identify.identifiability.not_identified`). Every parameter set in that region fits the
measured channels about as well, and each predicts its own plate. By the law of total variance the spread of the
estimate is the filter's (given the parameters) plus the variance of the prediction across the plausible
parameter sets:

    σ² = σ²_filter + Var_θ[x̂(θ)]

The second term is estimated by Monte Carlo: DRAWS parameter sets, the identified ones drawn from the normal
law of the stated covariance in the coordinates the fit uses (log for positive parameters, so a draw stays
positive), the not-identified ones uniformly over their search range in the same coordinate (the data say
nothing beyond the bounds the model file sets), each simulated open loop on the run. Open loop, because the
term is added only to states no sensor reads, which the sensors barely steer (their innovations reach them only
through the model's couplings); a measured state keeps the filter's spread, which its readings check (NIS).
Nothing here looks at what the band is later scored against: a right model with well-identified parameters
draws close together and the band stays the filter's.

The parameter draws stay inside one model's structure. Where other structures fit the same measured channels
about as well (diagnose's best model beside the model it extends), their predictions of the unread state are a
second, structural doubt: `form_spread` is the spread across those models' open-loop predictions (two models:
half their difference), added in quadrature (`combined`) as the law of total variance adds a further level.

Both stay inside structures the same measured channels were fitted to. The cool-down sweep reads the unread
plate a second way: each cool-down's fit (`benchlab.identify.cooldown`) takes the plate's start temperature from
the measured decay (T_P0), where the model's own simulation of the sweep has its plate at that moment. Their
disagreement, relative to the model's rise above ambient (`start_discrepancy`), is what the model cannot explain
about that node, measured without the truth; the band carries it as σ = r·|x̂_model − ϑ_ambient|
(`discrepancy_spread`), zero where the model's plate sits at ambient (a run's start), in proportion to how far the
model drives it. On the reference plant the model's plate is 20–50 K low at the sweep's starts (its capacity twice
the plant's, docs/observer.md), and r is 0.34–0.61.

A measured state keeps the filter's band, which its readings check; but the temperature wear needs is the friction
face's, which the sensor reads behind the face and through its own response, and the filter follows the sensor.
While the clutch slips, the open-loop model and that sensor disagree by what the model's structure cannot explain
at the node (`slipping_residual`); which of the two is nearer the face, no measured channel says. The wear of a
measured side is computed over a band widened by that miss, in quadrature with the filter's, taken on a run the
model was not fitted on: its own fitting run flatters it (reference plant, seeds 11 and 13: 0.8 and 0.7 K on the
Table 1 run it was fitted on, 3.4 and 3.9 K on the validation run).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from benchlab.identify.identifiability import not_identified
from benchlab.identify.spec import ParamSpec
from benchlab.model.catalog import model_spec
from benchlab.model.params import ModelParams
from benchlab.network.simulation import input_channels, simulate
from benchlab.observer.batch import STD_SUFFIX, Observation
from benchlab.report.resistance import correlations, standard_errors

if TYPE_CHECKING:
    from benchlab.identify.cooldown import CooldownResult

#: Parameter sets drawn: the spread's relative sampling error is about 1/√(2·DRAWS), 12 %.
DRAWS = 32
#: The filter's own σ of a widened state (the band given the parameter file), beside the widened `<name>_std`.
FILTER_STD_SUFFIX = "_filter_std"
#: The draws' seed: the same parameter file on the same run gives the same band.
SEED = 0


def _coordinate(spec: ParamSpec, value: float) -> float:
    """A value in the coordinate the fit moves it in: log for positive parameters, the value itself otherwise."""
    return float(np.log(value)) if spec.log else value


def _value(spec: ParamSpec, coordinate: float) -> float:
    """A coordinate back to a value, kept within the parameter's search bounds."""
    value = float(np.exp(coordinate)) if spec.log else coordinate
    return float(np.clip(value, spec.lower, spec.upper))


def parameter_draws(params: ModelParams, draws: int = DRAWS, seed: int = SEED) -> list[ModelParams]:
    """Parameter sets the identification holds plausible (module doc); [] when the file states no uncertainty."""
    specs = [s for s in model_spec(params.definition).free if s.name in params]
    errors, pairs = standard_errors(params), correlations(params)
    if not errors:
        return []
    loose = not_identified(specs, params, errors)
    fitted = [s for s in specs if s.name not in loose and s.name in errors]
    scale = np.array([errors[s.name] / abs(params[s.name]) if s.log else errors[s.name] for s in fitted])
    corr = np.array([[pairs.get((a.name, b.name), float(a.name == b.name)) for b in fitted] for a in fitted])
    covariance = corr * np.outer(scale, scale)
    rng = np.random.default_rng(seed)
    centre = np.array([_coordinate(s, params[s.name]) for s in fitted])
    out = []
    for row in rng.multivariate_normal(centre, covariance, size=draws, method="eigh") if fitted else [[]] * draws:
        values = dict(params) | {s.name: _value(s, x) for s, x in zip(fitted, row)}
        for spec in (s for s in specs if s.name in loose):
            values[spec.name] = _value(spec, rng.uniform(_coordinate(spec, spec.lower), _coordinate(spec, spec.upper)))
        out.append(ModelParams(params.definition, values, params.extra))
    return out


def model_spread(run: pd.DataFrame, params: ModelParams, channels: Sequence[str], draws: int = DRAWS
                 ) -> pd.DataFrame:
    """Per channel the standard deviation (K) of the open-loop prediction across `parameter_draws`, on the run's
    grid (the channels the model simulates); zeros when the parameter file states no uncertainty. The draws are
    taken in one at a time (Welford's running mean and sum of squares): 32 predictions of a long run are never held
    together (a week at 10 ms would be 15 GB), nor stacked into one array to be reduced."""
    sets = parameter_draws(params, draws)
    if not sets:
        return pd.DataFrame({c: np.zeros(len(run)) for c in channels}, index=run.index)
    first = simulate(run, sets[0], params.network)
    named = [c for c in channels if c in first.columns]
    mean = first[named].to_numpy(dtype=float, copy=True)
    squares = np.zeros_like(mean)
    for count, draw in enumerate(sets[1:], start=2):
        values = simulate(run, draw, params.network)[named].to_numpy()
        delta = values - mean
        mean += delta / count
        squares += delta * (values - mean)
    return pd.DataFrame(np.sqrt(squares / (len(sets) - 1)), columns=named, index=run.index)


def form_spread(run: pd.DataFrame, models: Sequence[ModelParams], channels: Sequence[str]) -> pd.DataFrame:
    """Per channel the standard deviation (K, population) across the open-loop predictions of `models`, structures
    that fit the measured channels about as well (module doc); the channels every model simulates."""
    predictions = [simulate(run, p, p.network) for p in models]
    named = [c for c in channels if all(c in prediction.columns for prediction in predictions)]
    spread = np.std([prediction[named].to_numpy() for prediction in predictions], axis=0)
    return pd.DataFrame(spread, columns=named, index=run.index)


def combined(*spreads: pd.DataFrame) -> pd.DataFrame:
    """Independent spreads of the same channels added in quadrature (a channel missing from one counts as 0)."""
    names = list(dict.fromkeys(c for spread in spreads for c in spread.columns))
    total = sum(spread.reindex(columns=names, fill_value=0.0).to_numpy() ** 2 for spread in spreads)
    return pd.DataFrame(np.sqrt(total), columns=names, index=spreads[0].index)


def start_discrepancy(points: "Sequence[CooldownResult]", time_s: np.ndarray, simulated_c: np.ndarray,
                      ambient_c: float) -> float | None:
    """RMS over the cool-downs of (T_P0 − the model's plate at the cool-down's start) / (that plate − ambient): how
    far the sweep's reading of the unread plate lies from the model's, relative to the model's rise (module doc);
    None without a cool-down that read it."""
    rows = [(p.T_P0, simulated_c[min(np.searchsorted(time_s, p.t_start), len(time_s) - 1)]) for p in points
            if np.isfinite(p.T_P0)]
    relative = [(read - model) / (model - ambient_c) for read, model in rows if abs(model - ambient_c) > 1.0]
    return float(np.sqrt(np.mean(np.square(relative)))) if relative else None


def discrepancy_spread(simulated: pd.Series, ambient_c: float, relative: float) -> pd.DataFrame:
    """σ = relative·|simulated − ambient| of the channel `simulated` names, on its index (module doc)."""
    return pd.DataFrame({simulated.name: relative * np.abs(simulated.to_numpy() - ambient_c)}, index=simulated.index)


def slipping_residual(run: pd.DataFrame, model: pd.DataFrame, channel: str) -> float:
    """RMS (K) of the open-loop model's miss on a measured channel over the samples where friction heat enters
    (friction power > 0): what the model cannot explain at that node while wear accrues (module doc)."""
    power = input_channels(run)["friction_power"]
    miss = model[channel].to_numpy() - run[channel].to_numpy()
    slipping = (power > 0) & np.isfinite(miss)
    return float(np.sqrt(np.mean(miss[slipping] ** 2))) if slipping.any() else 0.0


def widened(observation: Observation, spread: pd.DataFrame) -> Observation:
    """The observation with each state no sensor reads given σ = √(σ²_filter + spread²) (module doc); the
    filter's own σ kept as `<name>_filter_std`. A state without spread (no uncertainty stated) is left as it is."""
    estimate = observation.estimate.copy()
    model = observation.model
    for name in (model.names[s] for s in model.states):
        if name in spread.columns and name not in model.sensors and spread[name].to_numpy().any():
            filtered = estimate[name + STD_SUFFIX].to_numpy()
            estimate[name + FILTER_STD_SUFFIX] = filtered
            estimate[name + STD_SUFFIX] = np.sqrt(filtered ** 2 + spread[name].to_numpy() ** 2)
    return replace(observation, estimate=estimate)
