"""A run simulated block by block (benchlab.network.stream) gives the whole-run solver's states bit for bit."""

import numpy as np
import pandas as pd
import pytest

import benchlab
from benchlab.model.clutch import clutch_network
from benchlab.model.params import paper_params
from benchlab.network.simulation import initial_state, input_channels
from benchlab.network.solver import discretise, propagate
from benchlab.network.stream import RunChannels, stream_network


def _run(n: int = 5000, seed: int = 4) -> pd.DataFrame:
    """A clutch run with noisy engine speed (a new operating point nearly every sample), switching clutch state,
    and drop-outs in the measured flywheel temperature and the ambient, leading ones included."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    state = (np.sin(t / 3.0) > 0).astype(float)
    run = pd.DataFrame({"time": t, "engine_speed": 150 + 40 * np.sin(t) + rng.normal(0, 2, n),
                        "clutch_state": state, "friction_power": 3000 * state * rng.uniform(0.5, 1, n),
                        "T_flywheel": 40 + rng.normal(0, 0.1, n), "T_air": np.full(n, 35.0),
                        "T_housing": np.full(n, 30.0), "T_ambient": 25 + rng.normal(0, 0.05, n),
                        "T_engine": np.full(n, np.nan)})
    run.loc[:6, "T_flywheel"] = np.nan
    run.loc[rng.choice(n, 300, replace=False), "T_ambient"] = np.nan
    run.loc[:2, "T_ambient"] = np.nan
    run.attrs["dt"] = 0.01
    return run


@pytest.mark.parametrize("block", [1, 97, 1024, 10**6])
def test_blocks_give_the_whole_run_states_bit_for_bit(block):
    run = _run()
    network, params = clutch_network(), paper_params("nonlinear")
    channels = input_channels(run)
    x0 = initial_state(network, channels)
    want = propagate(discretise(network, params, channels, 0.01), x0)
    got = stream_network(network, params, RunChannels(pd.DataFrame(run, copy=False)), 0.01, x0, 1e-6, block)
    assert np.array_equal(got.T, want)


def test_run_channels_hold_drop_outs_as_input_channels_does():
    run = _run()
    held = input_channels(run)
    lazy = RunChannels(pd.DataFrame(run, copy=False))
    assert set(lazy) == set(held) and "T_engine" not in lazy  # a channel never measured is left out
    for name, values in held.items():
        assert np.array_equal(values, run[name].ffill().bfill().to_numpy())  # pandas' hold: an independent reference
        assert np.array_equal(lazy[name], values)
        assert np.array_equal(lazy.window(1000, 2345)[name], values[1000:2345])


def test_simulate_keeps_its_columns_and_values():
    run = _run()
    params = paper_params("nonlinear")
    sim = benchlab.simulate(run, params)
    network = clutch_network()
    channels = input_channels(run)
    states = propagate(discretise(network, params, channels, 0.01), initial_state(network, channels))[:-1]
    assert list(sim.columns) == list(network.outputs)
    for name, state in network.outputs.items():
        assert np.array_equal(sim[name].to_numpy(), states[:, network.state_names.index(state)])


@pytest.mark.parametrize("max_points", [1 << 13, 2])
def test_a_stream_kept_across_runs_gives_each_run_s_fresh_states(max_points, monkeypatch):
    """NetworkStream (the simulated bench's plant): operating points, law values and a repeated run's states kept
    from run to run change no bit of any run's states, whether a channel is the same array, a new array with the
    same values, or new values; also where the points are forgotten before every run (MAX_POINTS 2: the buffers
    kept, `_Points.clear`)."""
    from benchlab.network import stream as stream_module
    from benchlab.network.stream import NetworkStream

    monkeypatch.setattr(stream_module, "MAX_POINTS", max_points)
    from sim_bench.reference_plant import reference_network, reference_params

    network, params = reference_network(), reference_params()
    rng = np.random.default_rng(2)
    n = 300
    base = {"engine_speed": np.full(n, 1500.0), "clutch_speed": np.linspace(0, 1500, n),
            "clutch_state": (np.arange(n) > 100).astype(float), "friction_power": rng.uniform(0, 4000, n),
            "T_ambient": 22 + rng.normal(0, 0.01, n)}
    stream = NetworkStream(network, params, 0.01, 1e-6)
    x0 = np.linspace(30, 60, len(network.state_names))
    runs = []
    for temperature in (40.0, 40.0, 41.3, 41.3):  # the states' channels: repeated, then new values
        channels = dict(base)
        channels.update({f"_state_{s}": np.full(n, temperature + i) for i, s in enumerate(network.state_names)})
        runs.append(channels)
    runs.append(dict(runs[-1], engine_speed=base["engine_speed"] + 200.0))  # one channel changed, the rest kept
    runs.append(runs[-1])  # the very same channels: the last run's states again
    runs.append(dict(runs[0]))  # points met before, forgotten since where MAX_POINTS is 2
    for channels in runs:
        want = stream_network(network, params, channels, 0.01, x0, 1e-6)
        assert np.array_equal(stream.run(channels, x0), want)
