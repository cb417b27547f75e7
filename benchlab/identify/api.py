"""identify(): runs in, parameter set with uncertainty, fit statistics and residual analysis out.

The multi-start search takes each run's initial state from the data's start values; the final polish
then fits each run's starting ϑ_F, ϑ_A and ϑ_T as well (ϑ_P starts with ϑ_F, contract §2). A start
value carries its sensor's noise, and an initial error of a few hundredths of a kelvin in the slow
housing decays over the whole run: held fixed, it biased C_T, R_Feng and R_Tamb by many standard
errors (R_Feng by 9.5 % rms over ten 1 h runs, against 0.8 % with the states fitted). The fitted
starts serve the estimate only: the error figures and the residual tests are of the identified model
as `simulate`, `report` and every user run it, from the run's measured start (identify.residuals).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab._blas import single_threaded_blas
from benchlab.identify.data import FitData, prepare, scout_runs
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.identify.evaluate import evaluate
from benchlab.identify.fit import FitResult, fit_multistart
from benchlab.identify.residuals import residual_start, run_residuals
from benchlab.identify.spec import ModelSpec, ParamSpec
from benchlab.identify.uncertainty import (METHOD, Uncertainty, estimate_uncertainty, power_noise,
                                          temperature_input_noise)
from benchlab.model.catalog import model_spec
from benchlab.model.definition import ModelDefinition
from benchlab.model.params import ModelParams, check_params
from benchlab.progress import SILENT, Progress
from benchlab.network.simulation import simulate

INITIAL_STATE_RANGE_K = 20.0
#: Fitting steps from which a run's scouts fit its cheaper version (benchlab.identify.data.scout_runs): a shorter
#: run is cheap to scout as it is, and its cheaper version would hold few targets per parameter.
SCOUT_RUNS_FROM = 1000


@dataclass
class Identification:
    """Everything `benchlab identify` reports."""

    params: ModelParams
    fit: FitResult
    uncertainty: Uncertainty
    fitting: dict[str, dict]
    validation: dict[str, dict]
    residuals: dict[str, dict]  # run -> channel -> residual tests
    initial_states: dict[str, dict[str, dict[str, float]]]  # run -> channel -> value, standard_error

    def summary(self) -> dict:
        """The parameter file's extra keys: uncertainties, fit figures, residual tests, the parameters the runs do not
        identify (with why and what would), warnings."""
        u = self.uncertainty
        names = [k for k in self.params if k in u.standard_errors]
        index = [u.names.index(k) for k in names]
        return {"uncertainty": {k: u.standard_errors[k] for k in names},
                "uncertainty_method": dict(METHOD),
                "uncertainty_bandwidths": {"values": u.bandwidths, "unit": "fitting steps"},
                "uncertainty_sources": {source: {k: v[k] for k in names} for source, v in u.sources.items()},
                "correlation": {"names": names,
                                "matrix": np.round(u.correlation[np.ix_(index, index)], 4).tolist()},
                "initial_states": self.initial_states,
                "fit": {"fitting": self.fitting, "validation": self.validation, "starts": self.fit.starts,
                        "start_costs": self.fit.start_costs, "residuals": self.residuals},
                "not_identified": self.uncertainty.not_identified,
                "warnings": self.uncertainty.warnings}


def initial_channels(spec: ModelSpec) -> list[str]:
    """The measured channels the states start from (ϑ_P and ϑ_F both from the flywheel's: contract §2)."""
    return list(dict.fromkeys(spec.network.initial[s] for s in spec.network.state_names))


def with_initial_states(spec: ModelSpec, datasets: Sequence[FitData], channels: Sequence[str] = ()) -> ModelSpec:
    """The spec plus each run's initial temperature of each such channel (or of `channels`) as a free parameter,
    from its first reading."""
    extra = []
    for data in datasets:
        for channel in channels or initial_channels(spec):
            first = data.first_valid[channel]
            extra.append(ParamSpec(f"init_{channel}@{data.name}", first, first - INITIAL_STATE_RANGE_K,
                                   first + INITIAL_STATE_RANGE_K, log=False, unit="degC", scale=1.0))
    return spec.with_free(tuple(extra))


def late_channels(runs: Sequence[pd.DataFrame], channels: Sequence[str]) -> list[str]:
    """The channels states start from whose first reading comes after a run's first row (a logger that started
    late, an imported file): their value at t = 0 is unknown, so the search fits it too. Taken from the first
    reading instead, a flywheel already heated by the first launch bent C_P from 1789 to 414 J/K on a 30 min run
    with 3 s missing."""
    late = []
    for channel in channels:
        if any(channel in run and len(run) and not np.isfinite(run[channel].to_numpy()[0]) for run in runs):
            late.append(channel)
    return late


def _labels(runs: Sequence[pd.DataFrame], prefix: str) -> list[str]:
    """Each run's source (its file), numbered where two runs share one."""
    names = [str(run.attrs.get("source", f"{prefix}{i}")) for i, run in enumerate(runs)]
    return [name if names.count(name) == 1 else f"{name} #{i}" for i, name in enumerate(names)]


@single_threaded_blas
def identify(runs: Sequence[pd.DataFrame], model: "str | ModelDefinition" = "nonlinear",
             fixed: Mapping[str, float] | None = None, validate: Sequence[pd.DataFrame] = (), starts: int = 6,
             seed: int = 0, step_s: float = FIT_STEP_S, progress: Progress = SILENT) -> Identification:
    """Fit a model (a built-in name, a model file or a checked definition) to all runs at once at the fitting
    step `step_s`, then measure it on them and on validation runs.

    `progress` gets one task in fits: the multistart's scouts (on cheaper versions of the runs, `scout_runs`), and
    its polish on the runs themselves, which fits the start states too.
    """
    spec = model_spec(model).with_fixed(dict(fixed or {}))
    datasets = [prepare(run, step_s, name=f"run{i}", network=spec.network) for i, run in enumerate(runs)]
    late = late_channels(runs, initial_channels(spec))
    with progress.task(f"identify {spec.definition.label}", starts + 1, unit="fit") as task:
        result = fit_multistart(with_initial_states(spec, datasets, late) if late else spec, datasets, starts=starts,
                                seed=seed, task=task,
                                scout_data=[scout_runs(data) if len(data) >= SCOUT_RUNS_FROM else data
                                            for data in datasets],
                                polish=with_initial_states(spec, datasets))
    model_names = [p.name for p in spec.free]
    params = check_params(spec.definition, {k: v for k, v in result.params.items() if "@" not in k}, "identify")
    noise = [{"friction_power": power_noise(run, data.block, len(data)), **temperature_input_noise(data)}
             for run, data in zip(runs, datasets)]
    uncertainty = estimate_uncertainty(result, datasets, noise, model_names)
    labels = _labels(runs, "run")
    initial = {label: {c: {"value": result.params[f"init_{c}@{data.name}"],
                           "standard_error": uncertainty.standard_errors[f"init_{c}@{data.name}"]}
                       for c in initial_channels(spec)} for label, data in zip(labels, datasets)}
    fitting = {label: evaluate(r, params) for label, r in zip(labels, runs)}
    validation = {label: evaluate(r, params) for label, r in zip(_labels(validate, "validation"), validate)}
    residuals = {label: run_residuals(r, simulate(r, params, initial=residual_start(r, params, data)), params,
                                      data).tests
                 for label, r, data in zip(labels, runs, datasets if step_s == FIT_STEP_S else [None] * len(runs))}
    return Identification(params, result, uncertainty, fitting, validation, residuals, initial)


def parse_fixed(items: Sequence[str], source: str = "--fix") -> dict[str, float]:
    """`NAME=VALUE` strings to a dict; raises ValueError naming the bad item."""
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"{source} {item!r}: expected NAME=NUMBER") from None
        if not np.isfinite(out[name.strip()]):
            raise ValueError(f"{source} {item!r}: expected a finite number")
    return out
