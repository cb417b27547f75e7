"""Lining temperatures from the thermal model: ϑ_P for the plate side, ϑ_F for the flywheel side, ϑ_A for the spring."""

from __future__ import annotations

from dataclasses import replace

import pandas as pd

from benchlab.clutch import clutch_network
from benchlab.errors import InputError
from benchlab.network import Source, ThermalNetwork
from benchlab.params import ModelParams
from benchlab.simulation import simulate

DEFAULT_SPLIT = 0.5


def heat_split(params: ModelParams, source: str = "<params>") -> float:
    """Fraction of the friction power going to the pressure plate: the params file's `split`, else 0.5 (eq. 6-7)."""
    value = params.get("split", getattr(params, "extra", {}).get("split", DEFAULT_SPLIT))
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise InputError(source, "split", f"a plate fraction in [0, 1], got {value!r}")
    return float(value)


def split_network(split: float) -> ThermalNetwork:
    """The paper's clutch with the friction power divided `split` : 1 - split between plate and flywheel."""
    network = clutch_network()
    if split == DEFAULT_SPLIT:
        return network
    sources = (Source("P", lambda p, ch: split * ch["friction_power"], "plate share"),
               Source("F", lambda p, ch: (1.0 - split) * ch["friction_power"], "flywheel share"))
    return replace(network, sources=sources)


def lining_temperatures(run: pd.DataFrame, params: ModelParams, split: float) -> pd.DataFrame:
    """The model's T_pressure_plate, T_flywheel, T_air (degC) on the run's grid, with the heat split applied."""
    return simulate(run, params, split_network(split))
