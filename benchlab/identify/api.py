"""identify(): runs in, parameter set with uncertainty, fit statistics and residual analysis out."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.identify.data import FitData, prepare
from benchlab.identify.evaluate import evaluate
from benchlab.identify.fit import FitResult, fit_multistart, simulate_outputs
from benchlab.identify.residuals import residual_tests
from benchlab.identify.spec import clutch_spec
from benchlab.identify.uncertainty import Uncertainty, estimate_uncertainty
from benchlab.params import ModelParams

RESIDUAL_INPUTS = ("friction_power", "engine_speed", "clutch_state")


@dataclass
class Identification:
    """Everything `benchlab identify` reports."""

    params: ModelParams
    fit: FitResult
    uncertainty: Uncertainty
    fitting: dict[str, dict]
    validation: dict[str, dict]
    residuals: dict[str, dict]

    def summary(self) -> dict:
        """The parameter file's extra keys: uncertainties, fit figures, residual tests, warnings."""
        return {"uncertainty": self.uncertainty.standard_errors,
                "fit": {"fitting": self.fitting, "validation": self.validation, "starts": self.fit.starts,
                        "start_costs": self.fit.start_costs, "residuals": self.residuals},
                "warnings": self.uncertainty.warnings}


def _residual_analysis(result: FitResult, datasets: Sequence[FitData]) -> dict[str, dict]:
    out = {}
    data = datasets[0]
    sim = simulate_outputs(result.spec.network, result.params, data)
    for c, target in data.targets.items():
        inputs = {k: data.channels[k] for k in RESIDUAL_INPUTS if k in data.channels}
        out[c] = residual_tests(sim[c] - target, inputs)
    return out


def identify(runs: Sequence[pd.DataFrame], model: str = "nonlinear", fixed: Mapping[str, float] | None = None,
             validate: Sequence[pd.DataFrame] = (), starts: int = 6, seed: int = 0) -> Identification:
    """Fit the paper's model to all runs at once, then measure it on them and on validation runs."""
    spec = clutch_spec(model).with_fixed(dict(fixed or {}))
    datasets = [prepare(run, name=run.attrs.get("source", f"run{i}")) for i, run in enumerate(runs)]
    result = fit_multistart(spec, datasets, starts=starts, seed=seed)
    values = {k: v for k, v in result.params.items()}
    params = ModelParams(model, values)
    name = lambda i, run: str(run.attrs.get("source", f"run{i}"))  # noqa: E731
    fitting = {name(i, r): evaluate(r, params) for i, r in enumerate(runs)}
    validation = {name(i, r): evaluate(r, params) for i, r in enumerate(validate)}
    return Identification(params, result, estimate_uncertainty(result), fitting, validation,
                          _residual_analysis(result, datasets))


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
