"""Parameter files (contract sections 2 and 6): read, check, write.

A parameter file names its model: `"model": "linear"` or `"nonlinear"` (the built-in clutch model files), or
any model whole under `"network"` (the model file's tables as JSON), so one file is enough to simulate,
report, diagnose from or estimate wear with.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from benchlab.errors import InputError, read_document
from benchlab.model.build import build_network
from benchlab.model.catalog import BUILTIN, builtin
from benchlab.model.definition import ModelDefinition, parse_model
from benchlab.network import ThermalNetwork
from benchlab.outputs import write_text
from benchlab.values import finite_number

#: Contract section 2: a linear parameter file may omit eq. (11)'s terms and means a1 = a2 = 0.
LINEAR_CONVECTION = {"a1": 0.0, "b1": 0.0, "a2": 0.0, "b2": 0.0}


class ModelParams(dict):
    """Parameter name -> value, plus the model (its definition and label) and any extra keys of the file."""

    def __init__(self, definition: ModelDefinition, values: Mapping[str, float],
                 extra: Mapping[str, Any] | None = None) -> None:
        super().__init__(values)
        self.definition = definition
        self.extra = dict(extra or {})
        self._network: ThermalNetwork | None = None

    @property
    def model(self) -> str:
        """The model's name as the file carries it: linear, nonlinear or the model file's name."""
        return self.definition.label

    @property
    def network(self) -> ThermalNetwork:
        """The model's thermal network, built once."""
        if self._network is None:
            self._network = build_network(self.definition)
        return self._network


def _strictly_positive(model: ModelDefinition) -> set[str]:
    """Parameters that divide: heat capacities, time constants and resistances that are one parameter alone."""
    return (set(model.nodes.values()) | {g.time_constant for g in model.lags}
            | {l.resistance.text.strip() for l in model.links if l.resistance.text.strip() in model.parameters})


def check_params(model: "str | ModelDefinition", values: Mapping[str, Any], source: str = "<params>") -> ModelParams:
    """Validate names, types and signs against the model; fixed parameters come from the model file; a linear
    clutch gets a1 = a2 = 0."""
    if not isinstance(model, ModelDefinition):
        if not isinstance(model, str) or model not in BUILTIN:
            raise InputError(source, "model", f"one of {', '.join(BUILTIN)} (or a \"network\"), got {model!r}")
        model = builtin(model)
    positive = _strictly_positive(model)
    clean: dict[str, float] = {}
    for name, param in model.parameters.items():
        if param.fixed is not None and name not in values:
            clean[name] = param.fixed
            continue
        if name not in values:
            raise InputError(source, f"params.{name}", "a number (missing)")
        value = values[name]
        if finite_number(value) is None:
            raise InputError(source, f"params.{name}", f"a finite number, got {value!r}")
        if name in positive and value <= 0:
            raise InputError(source, f"params.{name}", f"a positive value, got {value!r}")
        if param.min >= 0 and value < 0:
            raise InputError(source, f"params.{name}", f"a value >= 0, got {value!r}")
        clean[name] = float(value)
    if model.alias == "linear":
        clean.update(LINEAR_CONVECTION)
    extras = {k: float(v) for k, v in values.items() if k not in clean and finite_number(v) is not None}
    return ModelParams(model, {**extras, **clean})


def load_params(path: "str | os.PathLike[str]", model: ModelDefinition | None = None) -> ModelParams:
    """Read a parameter file; raise InputError naming the file and field on any defect.

    `model` (a command's `--model`) takes the place of the file's own model; its parameters must be in the file.
    """
    path = Path(path)
    doc = read_document(path, "parameter file", json.loads, (json.JSONDecodeError,), "JSON")
    if not isinstance(doc, dict):
        raise InputError(path, "file", "a JSON object")
    if not isinstance(doc.get("params"), dict):
        raise InputError(path, "params", "an object of parameter values")
    if model is None and "network" in doc:
        model = parse_model(doc["network"], path, prefix="network.")
    params = check_params(model or doc.get("model", "nonlinear"), doc["params"], str(path))
    params.extra = {k: v for k, v in doc.items() if k not in ("model", "params", "units", "network")}
    return params


def save_params(path: "str | os.PathLike[str]", params: ModelParams, extra: Mapping[str, Any] | None = None) -> None:
    """Write a parameter file: the contract's keys first (with "network" for a model that is not built in), then
    any extra keys (statistics, uncertainty)."""
    model = params.definition
    dropped = LINEAR_CONVECTION if model.alias == "linear" else {}
    values = {k: params[k] for k in model.parameters} | {k: v for k, v in params.items()
                                                         if k not in model.parameters and k not in dropped}
    units = {k: p.unit for k, p in model.parameters.items() if p.unit}
    doc: dict[str, Any] = {"model": model.label, "params": values, "units": units}
    if model.alias is None:
        doc["network"] = model.to_doc()
    doc.update({**params.extra, **dict(extra or {})})
    write_text(path, json.dumps(doc, indent=2, default=float) + "\n")


def paper_params(model: str = "nonlinear") -> ModelParams:
    """The contract's example values: a plausible clutch for demos and simulated benches."""
    values = {"C_P": 1800.0, "C_F": 3700.0, "C_A": 2000.0, "C_T": 13000.0, "R_AT": 0.05, "R_Feng": 2.0,
              "R_Tamb": 0.1, "R0": 0.15, "a1": 0.35, "b1": -0.001, "a2": 0.45, "b2": -0.0015}
    return check_params(model, values)
