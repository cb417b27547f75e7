"""Drive a thermal network with a run's measured inputs (contract section 4: `simulate`)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from benchlab.errors import InputError
from benchlab.network.sensors import reading, temperature_of
from benchlab.network.structure import Params, ThermalNetwork
from benchlab.network.solver import DEFAULT_RESOLUTION, run_network
from benchlab.network.stream import RunChannels, first_valid_index, hold, stream_network


def _held(values: np.ndarray) -> np.ndarray:
    """Drop-outs (NaN) held at the last valid value, leading ones at the first (the stream's compiled hold);
    untouched if there are none. The channel holds a valid value."""
    if not np.isnan(values).any():
        return values
    out = np.empty(len(values))
    hold(np.ascontiguousarray(values), float(values[first_valid_index(values)]), out)
    return out


def input_channels(run: pd.DataFrame) -> dict[str, np.ndarray]:
    """Every channel as an array with drop-outs held at the last valid value (zero-order hold, as between
    samples), for the network's laws and boundaries; a channel never measured (all NaN) is left out.

    Measured temperatures are held too: a law may read them (radiation, learned terms), and the first held
    value is the first measured one, which starts the states. Fitting targets come from the run itself.
    """
    bare = pd.DataFrame(run, copy=False)  # same columns without attrs: pandas deep-copies attrs on every run[name]
    channels = {}
    for name in bare.columns:
        values = bare[name].to_numpy(np.float64)
        if name == "time" or not np.isnan(values).all():
            channels[name] = _held(values)
    return channels


def model_network(params: Params, network: ThermalNetwork | None = None) -> ThermalNetwork:
    """The network to simulate: the one given, else the parameter file's model, else the paper's nonlinear clutch."""
    if network is not None:
        return network
    if hasattr(params, "network"):
        return params.network
    from benchlab.model.clutch import clutch_network

    return clutch_network()


def initial_state(network: ThermalNetwork, channels: Mapping[str, np.ndarray], source: str = "<run>",
                  overrides: Mapping[str, float] | None = None, params: Params | None = None,
                  seconds: float = 0.0) -> np.ndarray:
    """Each state starts at the first valid sample of the channel it is initialised from, the temperature that
    reading stands for where the channel's sensor is calibrated (`params` then holds its calibration; `seconds`: when
    the channels start, since the run's first sample)."""
    overrides = dict(overrides or {})
    x0 = []
    for state in network.state_names:
        if state in overrides:
            x0.append(float(overrides[state]))
            continue
        channel = network.initial[state]
        first = _first_valid(channels, channel)
        if first is None:
            raise InputError(source, f"/aligned/{channel}", f"a valid sample to start state {state} from")
        x0.append(started_from(network, params, channel, first, seconds))
    return np.array(x0)


def started_from(network: ThermalNetwork, params: Params | None, channel: str, value: float,
                 seconds: float = 0.0) -> float:
    """The temperature a state starts at from its channel's first reading, taken `seconds` after the run's start."""
    calibration = network.calibrations.get(channel)
    return value if calibration is None else float(temperature_of(calibration, params, value, seconds))


def output_frame(network: ThermalNetwork, params: Params, states: np.ndarray, dt: float,
                 index: pd.Index) -> pd.DataFrame:
    """The outputs' readings (degC) from the state-major states (states × samples): each output reads its state
    through its sensor's calibration (benchlab.network.sensors), t the seconds since the run's first sample."""
    rows = {name: i for i, name in enumerate(network.state_names)}
    columns = {}
    seconds = np.arange(len(index)) * dt if network.calibrations else 0.0
    for channel, state in network.outputs.items():
        columns[channel] = reading(network.calibrations.get(channel), params, states[rows[state], :len(index)],
                                   seconds)
    return pd.DataFrame(columns, index=index, copy=False)


def _first_valid(channels: Mapping[str, np.ndarray], name: str) -> float | None:
    """A channel's first finite sample, None where it has none (or is absent)."""
    if isinstance(channels, RunChannels):
        return channels.first_valid(name)
    values = channels.get(name)
    at = -1 if values is None else first_valid_index(np.asarray(values, dtype=np.float64))
    return None if at < 0 else float(values[at])


def simulate(run: pd.DataFrame, params: Params, network: ThermalNetwork | None = None,
             initial: Mapping[str, float] | None = None) -> pd.DataFrame:
    """The model's temperatures (degC) on the run's grid, one column per output and simulated channel
    (the clutch: T_pressure_plate, T_flywheel, T_air, T_housing)."""
    network = model_network(params, network)
    channels = RunChannels(pd.DataFrame(run, copy=False))  # read on demand, block by block (no attrs deep-copied)
    x0 = initial_state(network, channels, run.attrs.get("source", "<run>"), initial, params)
    dt = float(run.attrs["dt"])
    states = stream_network(network, params, channels, dt, x0, DEFAULT_RESOLUTION)
    if states is None:
        states = run_network(network, params, input_channels(run), dt, x0).T
    if network.calibrations:
        return output_frame(network, params, states, dt, run.index)
    index = {name: i for i, name in enumerate(network.state_names)}
    rows = [index[state] for state in network.outputs.values()]
    # state-major: each output's series is a contiguous row, which the frame takes without a copy
    chosen = states[:len(rows)] if rows == list(range(len(rows))) else states[rows]
    return pd.DataFrame(chosen[:, :-1].T, columns=list(network.outputs), index=run.index, copy=False)
