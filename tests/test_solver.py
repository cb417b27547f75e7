"""The exact-discretisation simulator against an independent ODE solution and physical invariants."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

import benchlab
from benchlab.model.clutch import clutch_network, convection_resistance
from benchlab.model.params import paper_params
from benchlab.network.solver import (Discretised, _horner_step, _propagate, _propagate4, _propagate_combined44,
                                     _sparse_horner_step, _zoh)


def _reference(run: pd.DataFrame, params, x0: np.ndarray) -> np.ndarray:
    """solve_ivp (rtol 1e-10) of eq. 6-9 with (11), inputs held between samples, piece by piece."""
    p = params
    ch = {c: run[c].to_numpy() for c in run.columns}
    r = np.broadcast_to(convection_resistance(p, ch), len(run))
    dt = run.attrs["dt"]
    out = np.empty((len(run), 4))
    x = x0.copy()
    for k in range(len(run)):
        out[k] = x
        P, amb, R = ch["friction_power"][k], ch["T_ambient"][k], r[k]

        def rhs(_t, s):
            tp, tf, ta, tt = s
            return [(P / 2 - (tp - ta) / R) / p["C_P"],
                    (P / 2 - (tf - ta) / R - (tf - amb) / p["R_Feng"]) / p["C_F"],
                    ((tf - ta) / R + (tp - ta) / R - (ta - tt) / p["R_AT"]) / p["C_A"],
                    ((ta - tt) / p["R_AT"] - (tt - amb) / p["R_Tamb"]) / p["C_T"]]
        x = solve_ivp(rhs, (0, dt), x, method="DOP853", rtol=1e-10, atol=1e-10).y[:, -1]
    return out


def _piecewise_input(n: int, dt: float, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    blocks = rng.integers(1, 40, size=n)
    idx = np.repeat(np.arange(n), blocks)[:n]
    frame = pd.DataFrame({
        "time": np.arange(n) * dt,
        "engine_speed": rng.choice([800.0, 1000.0, 2000.0, 3000.0], size=n)[idx],
        "clutch_state": rng.choice([0.0, 1.0], size=n)[idx],
        "friction_power": rng.choice([0.0, 0.0, 5000.0, 20000.0], size=n)[idx],
        "T_ambient": 20.0 + rng.normal(0, 1, size=n)[idx],
        "T_flywheel": np.full(n, 60.0), "T_air": np.full(n, 40.0), "T_housing": np.full(n, 30.0),
    })
    frame.attrs["dt"] = dt
    return frame


@pytest.mark.parametrize("model", ["linear", "nonlinear"])
def test_matches_independent_ode_solution(model):
    run = _piecewise_input(400, 0.5, seed=3)
    params = paper_params(model)
    sim = benchlab.simulate(run, params)
    ref = _reference(run, params, np.array([60.0, 60.0, 40.0, 30.0]))
    got = sim[["T_pressure_plate", "T_flywheel", "T_air", "T_housing"]].to_numpy()
    assert np.max(np.abs(got - ref)) < 1e-4


def test_stiff_air_node_is_stable_at_large_step():
    """A 1 J/K air node (time constant ~ 0.05 s) simulated at dt = 1 s stays bounded and exact."""
    run = _piecewise_input(200, 1.0, seed=4)
    params = paper_params("nonlinear")
    params["C_A"] = 1.0
    sim = benchlab.simulate(run, params)
    ref = _reference(run, params, np.array([60.0, 60.0, 40.0, 30.0]))
    assert np.max(np.abs(sim.to_numpy() - ref)) < 1e-4


def test_energy_balance_without_losses():
    """With the network isolated from its boundaries, all friction energy stays in the capacities."""
    n, dt = 5000, 0.01
    run = _piecewise_input(n, dt, seed=5)
    params = paper_params("linear")
    params.update(R_Feng=1e12, R_Tamb=1e12)
    sim = benchlab.simulate(run, params)
    stored = sum(params[c] * (sim[col].iloc[-1] - sim[col].iloc[0]) for c, col in
                 (("C_P", "T_pressure_plate"), ("C_F", "T_flywheel"), ("C_A", "T_air"), ("C_T", "T_housing")))
    energy_in = run["friction_power"].to_numpy()[:-1].sum() * dt
    assert stored == pytest.approx(energy_in, rel=1e-6)


def test_nan_in_a_temperature_channel_does_not_poison_others(short_run):
    run = short_run.copy()
    run.attrs = dict(short_run.attrs)
    run.loc[:500, "T_flywheel"] = np.nan
    run.loc[1000:3000, "T_ambient"] = np.nan
    sim = benchlab.simulate(run, paper_params())
    assert np.all(np.isfinite(sim.to_numpy()))
    assert sim["T_flywheel"].iloc[0] == pytest.approx(run["T_flywheel"].iloc[501])


def test_network_rejects_unknown_node():
    net = clutch_network()
    broken = net.with_link(net.links[0].__class__("P", "nowhere", lambda p, c: 1.0, "bad"))
    with pytest.raises(ValueError, match="nowhere"):
        broken.validate()


def _thermal_systems(n: int, m: int, points: int, capacity: tuple[float, float], seed: int, chain: bool = False):
    """Random conductance networks (symmetric, grounded) over random capacities; the last state a sensor lag.
    `chain`: each node linked to its neighbours only (a sparse A, as a network of many nodes is)."""
    rng = np.random.default_rng(seed)
    g = rng.uniform(0.1, 20.0, size=(points, n, n))
    g = (g + g.transpose(0, 2, 1)) / 2
    if chain:
        g *= np.abs(np.subtract.outer(np.arange(n), np.arange(n))) <= 1
    a = g.copy()
    idx = np.arange(n)
    a[:, idx, idx] = -(g.sum(axis=2) - g[:, idx, idx]) - rng.uniform(0.0, 1.0, size=(points, n))
    c = rng.uniform(*capacity, size=(points, n, 1))
    a /= c
    a[:, -1, :] = 0.0
    a[:, -1, 0], a[:, -1, -1] = 1 / 3.0, -1 / 3.0
    return a, rng.uniform(0.0, 1.0, size=(points, n, m)) / c


@pytest.mark.parametrize("n, m, capacity, dt, chain", [(4, 4, (1e3, 2e4), 0.01, False), (4, 4, (1e3, 2e4), 0.5, False),
                                                        (7, 5, (1e3, 2e4), 0.5, False), (6, 4, (1.0, 10.0), 1.0, False),
                                                        (13, 8, (5.0, 2e4), 0.01, True), (13, 8, (5.0, 2e4), 1.0, True)])
def test_batched_zoh_matches_scipy_expm(n, m, capacity, dt, chain):
    """The compiled Taylor/squaring ZOH equals scipy's expm of the augmented matrix to 1e-9 relative, dense and
    sparse (a chain of 13 nodes: _sparse_horner_step)."""
    a, b = _thermal_systems(n, m, 200, capacity, seed=n + m, chain=chain)
    ad, bd = _zoh(a, b, dt)
    aug = np.zeros((len(a), n + m, n + m))
    aug[:, :n, :n], aug[:, :n, n:] = a * dt, b * dt
    ref = scipy.linalg.expm(aug)
    for got, want in ((ad, ref[:, :n, :n]), (bd, ref[:, :n, n:])):
        scale = np.max(np.abs(want), axis=(1, 2), keepdims=True)
        assert np.max(np.abs(got - want) / scale) < 1e-9


def test_the_sparse_horner_step_adds_the_dense_step_s_products_bit_for_bit():
    """Issue 47: the row-wise step over A's non-zero columns (the reference clutch's 13 states) gives the dense step's
    every bit, zeros of A skipped: the same sums in the same order."""
    a = _thermal_systems(13, 8, 1, (5.0, 2e4), seed=5, chain=True)[0][0]
    cols, counts = np.zeros((13, 13), dtype=np.int64), np.zeros(13, dtype=np.int64)
    for i in range(13):
        nonzero = np.flatnonzero(a[i])
        cols[i, :len(nonzero)], counts[i] = nonzero, len(nonzero)
    assert counts.sum() * 3 <= 13 * 13  # the kernel takes the sparse step for it
    P = np.random.default_rng(6).normal(size=(13, 13))
    dense, sparse = P.copy(), P.copy()
    _horner_step(a, 0.01, 1 / 6, dense, np.empty((13, 13)))
    _sparse_horner_step(a, cols, counts, 0.01, 1 / 6, sparse, np.empty((13, 13)))
    assert np.array_equal(sparse.view(np.uint64), dense.view(np.uint64))
    assert not np.array_equal(dense, P)


def test_four_state_kernel_equals_general_kernel():
    a, b = _thermal_systems(4, 4, 50, (1e3, 2e4), seed=1)
    rng = np.random.default_rng(2)
    disc = Discretised(rng.integers(0, 50, size=3000), *_zoh(a, b, 0.5), rng.uniform(0, 100, size=(3000, 4)))
    x0 = np.array([60.0, 55.0, 40.0, 30.0])
    out4, out = np.empty((4, 3001)), np.empty((4, 3001))
    _propagate4(disc.op_index, disc.Ad, disc.Bd, disc.inputs, x0, out4, 0)
    _propagate(disc.op_index, disc.Ad, disc.Bd, disc.inputs, x0, out, 0)
    assert np.allclose(out4, out, rtol=1e-13, atol=1e-10)


def test_combined_matrices_give_the_separate_kernels_states_bit_for_bit():
    """The stream's [Ad Bd] records (four states, four inputs) add the same products in the same order as
    _propagate4."""
    a, b = _thermal_systems(4, 4, 50, (1e3, 2e4), seed=3)
    rng = np.random.default_rng(4)
    Ad, Bd = _zoh(a, b, 0.5)
    op_index, inputs = rng.integers(0, 50, size=3000), rng.uniform(0, 100, size=(3000, 4))
    x0 = rng.uniform(20, 60, size=4)
    want, got = np.empty((4, 3001)), np.empty((4, 3001))
    _propagate4(op_index, Ad, Bd, inputs, x0, want, 0)
    _propagate_combined44(op_index, np.concatenate([Ad, Bd], axis=2), inputs, x0, got, 0)
    assert np.array_equal(got, want)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc (Linux)")
def test_import_benchlab_keeps_blas_single_threaded():
    """`import benchlab` before numpy leaves OpenBLAS without worker threads (tiny expm: 15 ms threaded, 0.01 ms not)."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    code = "import benchlab, os, numpy, scipy.linalg; print(len(os.listdir('/proc/self/task')))"
    threads = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert int(threads) == 1
