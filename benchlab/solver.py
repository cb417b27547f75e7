"""Exact zero-order-hold simulation of a thermal network driven by sampled channels.

Between two samples the inputs (heat flows, boundary temperatures) and the operating point
(link resistances) are held, so the state update over one step is exactly
x[k+1] = Ad x[k] + Bd u[k] with [Ad Bd] from the matrix exponential of the augmented
continuous system. Operating points are keyed by their conductances, quantised to a relative
resolution of `resolution` (1e-6 by default: far below any sensor's error), and
each distinct one is discretised once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.linalg
from numba import njit

from benchlab.network import Channels, Params, ThermalNetwork, as_samples

DEFAULT_RESOLUTION = 1e-6


@dataclass(frozen=True)
class Discretised:
    """Per-sample operating point index plus the discrete matrices of every distinct point."""

    op_index: np.ndarray  # (N,) int64 into Ad/Bd
    Ad: np.ndarray  # (M, n, n)
    Bd: np.ndarray  # (M, n, m)
    inputs: np.ndarray  # (N, m) heat flows (W) then boundary temperatures (degC)


def _conductances(network: ThermalNetwork, params: Params, channels: Channels, n: int) -> list[np.ndarray | float]:
    out: list[np.ndarray | float] = []
    for link in network.links:
        r = np.asarray(link.resistance(params, channels), dtype=np.float64)
        if np.any(~np.isfinite(r)) or np.any(r <= 0):
            raise ValueError(f"resistance of link {link.label or (link.a, link.b)} is not positive and finite")
        out.append(float(1.0 / r) if r.ndim == 0 else 1.0 / r)
    return out


def _system_matrices(network: ThermalNetwork, params: Params, conductances: list[np.ndarray],
                     n_ops: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous A (n_ops, n, n) and B (n_ops, n, m) for each operating point."""
    states = {name: i for i, name in enumerate(network.state_names)}
    bcol = {b.name: len(network.sources) + j for j, b in enumerate(network.boundaries)}
    n, m = len(states), len(network.sources) + len(network.boundaries)
    inv_c = np.zeros(n)
    for node in network.nodes:
        inv_c[states[node.name]] = 1.0 / params[node.capacity]
    A = np.zeros((n_ops, n, n))
    B = np.zeros((n_ops, n, m))
    for link, g in zip(network.links, conductances):
        ends = [(link.a, link.b), (link.b, link.a)]
        for here, there in ends:
            if here not in states:
                continue
            i = states[here]
            A[:, i, i] -= g * inv_c[i]
            if there in states:
                A[:, i, states[there]] += g * inv_c[i]
            else:
                B[:, i, bcol[there]] += g * inv_c[i]
    for k, src in enumerate(network.sources):
        i = states[src.node]
        B[:, i, k] = inv_c[i]
    for lag in network.lags:
        s, i, tau = states[lag.name], states[lag.node], params[lag.time_constant]
        A[:, s, s] = -1.0 / tau
        A[:, s, i] = 1.0 / tau
    return A, B


def _zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = A.shape[1], B.shape[2]
    aug = np.zeros((A.shape[0], n + m, n + m))
    aug[:, :n, :n] = A * dt
    aug[:, :n, n:] = B * dt
    E = scipy.linalg.expm(aug)
    return np.ascontiguousarray(E[:, :n, :n]), np.ascontiguousarray(E[:, :n, n:])


def _operating_points(conductances: list, n: int, resolution: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Group samples by quantised varying conductances; return index per sample and per-point values.

    Links that share one law (R_PA = R_FA) share one key column; the key columns are combined
    into one integer code per sample and factorised in linear time.
    """
    varying = [i for i, g in enumerate(conductances) if isinstance(g, np.ndarray)]
    if not varying:
        return np.zeros(n, dtype=np.int64), [np.array([g]) for g in conductances]
    columns: list[np.ndarray] = []
    column_of: dict[int, int] = {}
    for i in varying:
        same = next((j for j, c in enumerate(columns) if conductances[varying[j]] is conductances[i]
                     or np.array_equal(conductances[varying[j]], conductances[i])), None)
        if same is None:
            columns.append(np.rint(np.log(conductances[i]) / resolution).astype(np.int64))
            same = len(columns) - 1
        column_of[i] = same
    code = np.zeros(n, dtype=np.int64)
    uniques = []
    for col in columns:
        col_codes, col_uniques = pd.factorize(col)
        uniques.append(col_uniques)
        code = code * len(col_uniques) + col_codes
    op_index, op_codes = pd.factorize(code)
    op_index = op_index.astype(np.int64)
    per_column = []
    for col_uniques in reversed(uniques):
        per_column.append(col_uniques[op_codes % len(col_uniques)])
        op_codes = op_codes // len(col_uniques)
    per_column.reverse()
    per_op: list[np.ndarray] = []
    for i, g in enumerate(conductances):
        if i in column_of:
            per_op.append(np.exp(per_column[column_of[i]] * resolution))
        else:
            per_op.append(np.full(len(op_codes), g))
    return op_index, per_op


def discretise(network: ThermalNetwork, params: Params, channels: Channels, dt: float,
               resolution: float = DEFAULT_RESOLUTION) -> Discretised:
    """Evaluate the network's laws on the channels and discretise every distinct operating point."""
    n = len(next(iter(channels.values())))
    conductances = _conductances(network, params, channels, n)
    op_index, per_op = _operating_points(conductances, n, resolution)
    A, B = _system_matrices(network, params, per_op, len(per_op[0]) if per_op else 1)
    Ad, Bd = _zoh(A, B, dt)
    columns = [as_samples(s.heat_flow(params, channels), n) for s in network.sources]
    columns += [as_samples(b.temperature(channels), n) for b in network.boundaries]
    inputs = np.ascontiguousarray(np.stack(columns, axis=1)) if columns else np.zeros((n, 0))
    return Discretised(op_index, Ad, Bd, inputs)


@njit(cache=True, nogil=True)
def _propagate(op_index, Ad, Bd, inputs, x0, out):  # pragma: no cover - compiled
    n = x0.shape[0]
    m = inputs.shape[1]
    x = x0.copy()
    nxt = np.empty(n)
    steps = op_index.shape[0]
    for k in range(steps):
        for i in range(n):
            out[k, i] = x[i]
        a = Ad[op_index[k]]
        b = Bd[op_index[k]]
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += a[i, j] * x[j]
            for j in range(m):
                acc += b[i, j] * inputs[k, j]
            nxt[i] = acc
        for i in range(n):
            x[i] = nxt[i]
    for i in range(n):
        out[steps, i] = x[i]


def propagate(disc: Discretised, x0: np.ndarray) -> np.ndarray:
    """States (N + 1, n): row k at time k*dt from x0 at row 0; the last row is the state after the last step."""
    out = np.empty((disc.op_index.shape[0] + 1, x0.shape[0]))
    _propagate(disc.op_index, disc.Ad, disc.Bd, disc.inputs, np.asarray(x0, dtype=np.float64), out)
    return out


def run_network(network: ThermalNetwork, params: Params, channels: Channels, dt: float, x0: np.ndarray,
                resolution: float = DEFAULT_RESOLUTION) -> np.ndarray:
    """Simulate the network over the channels: states (N + 1, n), row k at time k*dt."""
    return propagate(discretise(network, params, channels, dt, resolution), x0)
