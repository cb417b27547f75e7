"""Parameter files (contract section 2): read, check, write."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from benchlab.clutch import CAPACITIES, LINEAR_PARAMS, NONLINEAR_PARAMS, RESISTANCES
from benchlab.errors import InputError
from benchlab.values import finite_number

UNITS = {"C_*": "J/K", "R_*, R0, a1, a2": "K/W", "b1, b2": "1/rpm"}
MODELS = ("linear", "nonlinear")


class ModelParams(dict):
    """Parameter name -> value, plus the model kind and any extra keys of the file."""

    def __init__(self, model: str, values: Mapping[str, float], extra: Mapping[str, Any] | None = None) -> None:
        super().__init__(values)
        self.model = model
        self.extra = dict(extra or {})


def check_params(model: str, values: Mapping[str, Any], source: str = "<params>") -> ModelParams:
    """Validate names, types and signs; fill a1 = a2 = 0 for a linear model."""
    if model not in MODELS:
        raise InputError(source, "model", f"one of {', '.join(MODELS)}, got {model!r}")
    required = LINEAR_PARAMS if model == "linear" else NONLINEAR_PARAMS
    clean: dict[str, float] = {}
    for name in required:
        if name not in values:
            raise InputError(source, f"params.{name}", "a number (missing)")
        value = values[name]
        if finite_number(value) is None:
            raise InputError(source, f"params.{name}", f"a finite number, got {value!r}")
        if name in CAPACITIES + RESISTANCES and value <= 0:
            raise InputError(source, f"params.{name}", f"a positive value, got {value!r}")
        if name in ("a1", "a2") and value < 0:
            raise InputError(source, f"params.{name}", f"a value >= 0, got {value!r}")
        clean[name] = float(value)
    if model == "linear":
        clean.update({"a1": 0.0, "b1": 0.0, "a2": 0.0, "b2": 0.0})
    extras = {k: float(v) for k, v in values.items() if k not in clean and _is_number(v)}
    return ModelParams(model, {**extras, **clean})


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def load_params(path: "str | os.PathLike[str]") -> ModelParams:
    """Read a parameter file; raise InputError naming the file and field on any defect."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(path, "file", "an existing parameter file (not found)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, "file", f"JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise InputError(path, "file", "a JSON object")
    if not isinstance(doc.get("params"), dict):
        raise InputError(path, "params", "an object of parameter values")
    params = check_params(doc.get("model", "nonlinear"), doc["params"], str(path))
    params.extra = {k: v for k, v in doc.items() if k not in ("model", "params", "units")}
    return params


def save_params(path: "str | os.PathLike[str]", params: ModelParams, extra: Mapping[str, Any] | None = None) -> None:
    """Write a parameter file: the contract's keys first, then any extra keys (statistics, uncertainty)."""
    names = LINEAR_PARAMS if params.model == "linear" else NONLINEAR_PARAMS
    values = {k: params[k] for k in names} | {k: v for k, v in params.items() if k not in NONLINEAR_PARAMS}
    doc = {"model": params.model, "params": values, "units": UNITS, **params.extra, **dict(extra or {})}
    Path(path).write_text(json.dumps(doc, indent=2, default=float) + "\n")


def paper_params(model: str = "nonlinear") -> ModelParams:
    """The contract's example values: a plausible clutch for demos and simulated benches."""
    values = {"C_P": 1800.0, "C_F": 3700.0, "C_A": 2000.0, "C_T": 13000.0, "R_AT": 0.05, "R_Feng": 2.0,
              "R_Tamb": 0.1, "R0": 0.15, "a1": 0.35, "b1": -0.001, "a2": 0.45, "b2": -0.0015}
    return check_params(model, values)
