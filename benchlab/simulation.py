"""Drive a thermal network with a run's measured inputs (contract section 4: `simulate`)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from benchlab.clutch import PREDICTED_CHANNELS, SIMULATED_CHANNELS, clutch_network
from benchlab.errors import InputError
from benchlab.network import Params, ThermalNetwork
from benchlab.solver import run_network

INPUT_CHANNELS = ("engine_speed", "clutch_state", "friction_power", "T_ambient")
SIGNAL_CHANNELS = ("clutch_speed", "clutch_torque", "load_torque")  # not model inputs; signals of extensions' laws


def _held(values: np.ndarray) -> np.ndarray:
    """Drop-outs (NaN) held at the last valid value, leading ones at the first; untouched if there are none."""
    if not np.isnan(values).any():
        return values
    return pd.Series(values).ffill().bfill().to_numpy()


def input_channels(run: pd.DataFrame) -> dict[str, np.ndarray]:
    """All channels as arrays, the model's inputs with drop-outs held at the last valid value.

    Inputs are held (zero-order hold, as between samples); measured temperatures the model
    predicts stay as they are, NaN included, because they only set the initial state.
    """
    source = run.attrs.get("source", "<run>")
    bare = pd.DataFrame(run, copy=False)  # same columns without attrs: pandas deep-copies attrs on every run[name]
    channels = {name: bare[name].to_numpy(np.float64) for name in bare.columns}
    for name in INPUT_CHANNELS + ("T_engine",):
        if name not in channels:
            if name == "T_engine":
                continue
            raise InputError(source, f"/aligned/{name}", "a model input channel (missing)")
        values = _held(channels[name])
        if np.isnan(values).all():
            if name == "T_engine":
                continue
            raise InputError(source, f"/aligned/{name}", "at least one valid sample")
        channels[name] = values
    for name in SIGNAL_CHANNELS:  # held like inputs where present; left out where never measured
        if name in channels:
            channels[name] = _held(channels[name])
            if np.isnan(channels[name]).all():
                del channels[name]
    for name in PREDICTED_CHANNELS:  # measured temperatures as signals for laws (radiation, learned terms)
        if name in channels:
            channels[f"{name}_filled"] = _held(channels[name])
    return channels


def initial_state(network: ThermalNetwork, channels: Mapping[str, np.ndarray], source: str = "<run>",
                  overrides: Mapping[str, float] | None = None) -> np.ndarray:
    """Each state starts at the first valid sample of the channel it is initialised from."""
    overrides = dict(overrides or {})
    x0 = []
    for state in network.state_names:
        if state in overrides:
            x0.append(float(overrides[state]))
            continue
        channel = network.initial[state]
        values = channels.get(channel)
        valid = np.flatnonzero(np.isfinite(values)) if values is not None else np.array([])
        if valid.size == 0:
            raise InputError(source, f"/aligned/{channel}", f"a valid sample to start state {state} from")
        x0.append(float(values[valid[0]]))
    return np.array(x0)


def simulate(run: pd.DataFrame, params: Params, network: ThermalNetwork | None = None,
             initial: Mapping[str, float] | None = None) -> pd.DataFrame:
    """The model's temperatures (degC) on the run's grid: T_pressure_plate, T_flywheel, T_air, T_housing."""
    network = network or clutch_network()
    channels = input_channels(run)
    x0 = initial_state(network, channels, run.attrs.get("source", "<run>"), initial)
    states = run_network(network, params, channels, float(run.attrs["dt"]), x0)[:-1]
    index = {name: i for i, name in enumerate(network.state_names)}
    columns = {name: states[:, index[network.outputs.get(name, state)]] for name, state in SIMULATED_CHANNELS.items()}
    return pd.DataFrame(columns, index=run.index)
