"""Lining temperatures from the thermal model: ϑ_P for the plate side, ϑ_F for the flywheel side, ϑ_A for the spring."""

from __future__ import annotations

import numpy as np
import pandas as pd

from benchlab.model.clutch import DEFAULT_MODEL
from benchlab.errors import InputError
from benchlab.model.build import build_network
from benchlab.model.catalog import builtin
from benchlab.model.definition import ModelDefinition, parse_model
from benchlab.network import ThermalNetwork
from benchlab.model.params import ModelParams
from benchlab.network.sensors import temperature_of
from benchlab.network.simulation import simulate
from benchlab.values import finite_number

DEFAULT_SPLIT = 0.5
#: The clutch model files' sources of the friction power P (eq. 6-7) and the channels wear reads.
SHARES = {"plate share": "P", "flywheel share": "F"}
LINING_CHANNELS = ("T_pressure_plate", "T_flywheel", "T_air")


def heat_split(params: ModelParams, source: str = "<params>") -> float:
    """Fraction of the friction power going to the pressure plate: the params file's `split`, else 0.5 (eq. 6-7)."""
    value = params.get("split", getattr(params, "extra", {}).get("split", DEFAULT_SPLIT))
    split = finite_number(value)
    if split is None or not 0.0 <= split <= 1.0:
        raise InputError(source, "split", f"a plate fraction in [0, 1], got {value!r}")
    return split


def split_model(split: float, model: ModelDefinition | None = None) -> ModelDefinition:
    """A built-in clutch model with the friction power divided `split` : 1 - split between plate and flywheel."""
    model = model or builtin(DEFAULT_MODEL)
    if split == DEFAULT_SPLIT:
        return model
    doc = model.to_doc()
    for entry in doc["sources"]:
        if entry["name"] in SHARES:
            share = split if SHARES[entry["name"]] == "P" else 1.0 - split
            entry["heat"] = f"{share!r}*friction_power"
    return parse_model(doc, model.source)


def split_network(split: float) -> ThermalNetwork:
    """The paper's clutch (nonlinear model file) with the friction power divided `split` : 1 - split."""
    return build_network(split_model(split))


def lining_network(params: ModelParams, split: float, source: str = "<params>") -> ThermalNetwork:
    """The network wear simulates: a built-in clutch model with the heat split applied, or the parameter file's own
    model (a split found by diagnose is in it), which must simulate the clutch's lining temperatures."""
    model = params.definition
    if model.alias is not None:
        return build_network(split_model(split, model))
    missing = [c for c in LINING_CHANNELS if c not in {**model.outputs, **model.simulated}]
    if missing:
        raise InputError(source, "network.simulated", f"a clutch model that simulates {', '.join(LINING_CHANNELS)} "
                                                      f"(wear needs the lining temperatures; {missing[0]} missing)")
    return params.network


def lining_temperatures(run: pd.DataFrame, params: ModelParams, split: float,
                        source: str = "<params>") -> pd.DataFrame:
    """The model's T_pressure_plate, T_flywheel, T_air (degC) on the run's grid, with the heat split applied: the
    nodes' own temperatures, not what a miscalibrated sensor reads of them (its reading turned back)."""
    network = lining_network(params, split, source)
    simulated = simulate(run, params, network)
    seconds = np.arange(len(run)) * float(run.attrs["dt"])
    for channel, calibration in network.calibrations.items():
        simulated[channel] = temperature_of(calibration, params, simulated[channel].to_numpy(), seconds)
    return simulated
