"""The library calls a batch task makes, in one place: loading runs, identify, diagnose, wear, parameter files.

Everything `benchlab batch` needs from the model code goes through here, so a change of those functions'
signatures is one edit. A model travels to the workers as text (a built-in name or a model file's absolute
path) and is read there, once per worker process (`resolve_model` caches it).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from benchlab.diagnose.engine import diagnose_runs
from benchlab.diagnose.report import summarise
from benchlab.identify.api import Identification, identify
from benchlab.model.catalog import resolve_model
from benchlab.model.definition import ModelDefinition
from benchlab.model.runs import load_runs
from benchlab.outputs import write_text
from benchlab.model.params import ModelParams, load_params, save_params
from benchlab.runfile import load_attrs
from benchlab.values import json_ready
from benchlab.wear.analysis import analyse_wear


def model_text(text: str) -> str:
    """`--model` checked on the client (bad input before any cluster starts) and as the workers will read it:
    a built-in name, or the model file's absolute path."""
    model = resolve_model(text)
    return text if model.alias == text else str(Path(text).resolve())


def model_of(text: str) -> ModelDefinition:
    """The model a task fits, from its text (`model_text`)."""
    return resolve_model(text)


def read_run(path: str, model: ModelDefinition) -> pd.DataFrame:
    """The run's /aligned channels, checked for what the model reads."""
    return load_runs([path], model)[0]


def read_attrs(path: str) -> dict[str, str]:
    """The run file's root attributes as text."""
    return load_attrs(path)


def read_params(path: str) -> ModelParams:
    """A parameter file (contract section 2)."""
    return load_params(path)


def fit(runs: Sequence[pd.DataFrame], model: ModelDefinition, starts: int, seed: int) -> Identification:
    """The model identified on all `runs` at once."""
    return identify(runs, model, starts=starts, seed=seed)


def save_fit(path: "str | os.PathLike[str]", result: Identification) -> None:
    """The identification as a parameter file with its uncertainties and fit figures."""
    save_params(path, result.params, result.summary())


def fitted(result: Identification) -> tuple[ModelParams, dict[str, float]]:
    """The fitted parameters and the standard error of each free one; NaN for one the runs do not identify (its
    standard error says nothing, and its trend leaves the run out)."""
    unidentified = result.uncertainty.not_identified
    return result.params, {name: float("nan") if name in unidentified else error
                           for name, error in result.uncertainty.standard_errors.items()}


def fit_figures(result: Identification) -> dict[str, object]:
    """RMSE (K) and NRMSE (%) on the fitted runs (mean over them), the number of identifiability warnings and the
    parameters the runs do not identify (their names)."""
    figures = list(result.fitting.values())
    return {"rmse_K": float(np.mean([f["rmse_K"] for f in figures])),
            "nrmse_pct": float(np.mean([f["nrmse_pct"] for f in figures])),
            "warnings": len(result.uncertainty.warnings),
            "not_identified": ", ".join(result.uncertainty.not_identified)}


def diagnosis(runs: Sequence[pd.DataFrame], baseline: ModelDefinition, seed: int) -> dict:
    """The contract's `diagnose --json` object for the runs taken together."""
    return summarise(diagnose_runs(runs, baseline, seed=seed), baseline.label)


def save_diagnosis(path: "str | os.PathLike[str]", result: dict) -> None:
    """The diagnosis as `benchlab diagnose --json` prints it."""
    write_text(path, json.dumps(result, default=float))


def wear(run: pd.DataFrame, params: ModelParams, params_source: str, seed: int) -> dict:
    """The `benchlab wear --json` object of one run (default clutch, NaN written as null)."""
    return json_ready(analyse_wear(run, params, seed=seed, params_source=params_source).as_dict())
