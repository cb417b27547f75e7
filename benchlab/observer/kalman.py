"""The Kalman filter's steps over a discretised thermal network, compiled: one home for the batch loop and the
online step.

Given the inputs, the network is linear in its states (resistances depend on channels such as engine speed and
clutch state, never on temperatures), and over one sample the zero-order-hold model x[k+1] = Ad x[k] + Bd u[k]
is exact. Process noise is a random heat flow on each node, held over the sample like every other input, so
it enters through the same Bd: its columns Γ (the network's noise sources, after the m real inputs) give
Qd = Γ diag(q) Γᵀ exactly. The linear time-varying Kalman filter on this model is therefore the exact
minimum-variance estimator. Sensors read states directly (the network's outputs) with independent noise, so
the measurement update is one scalar update per sensor that has a number: a NaN reading is skipped and the
covariance grows by the prediction alone.

A law can be corrected online (`adapt`): a random-walk resistance offset δ_j (K/W) is appended to the state,
and every link of law j conducts 1/(R_j + δ_j) instead of 1/R_j. Then a law depends on a state, the model is
no longer linear, and the prediction is extended (EKF): the correction's heat flows
dt·(1/(R_j + δ_j) − 1/R_j)·(S_j x + T_j u) are added to the exact step (S_j, T_j: dA/dg, dB/dg of the law's
links; first order in dt, which at 10 ms against time constants of a minute is far below the sensors'
resolution) and linearised at the estimate. With no law adapted both coincide with the linear filter.
"""

from __future__ import annotations

import numpy as np
from benchlab.jit import njit


@njit(cache=True, nogil=True)
def update(z, P, state, value, variance, gain):  # pragma: no cover - compiled
    """Measurement update with one reading `value` of state `state`, noise `variance` (K²); `gain` is scratch."""
    n = z.shape[0]
    s = P[state, state] + variance
    innovation = value - z[state]
    for i in range(n):
        gain[i] = P[i, state] / s
    for i in range(n):
        z[i] += gain[i] * innovation
    for i in range(n):
        for j in range(n):
            P[i, j] -= gain[i] * gain[j] * s


@njit(cache=True, nogil=True)
def predict(a, b, u, q, r, S, T, qd, dt, z, P, F, W):  # pragma: no cover - compiled
    """z = f(z, u), P = F P Fᵀ + Q for the temperatures z[:n] and the law corrections δ = z[n:].

    a, b: Ad, Bd = [network inputs | noise columns Γ] of the operating point; q: noise heat-flow variances (W²);
    r: resistance of each adapted law at this sample (K/W); S, T: dA/dg, dB/dg per adapted law; qd: variance
    added to each correction per sample. F (N, N) and W (N, N + 1) are scratch, N = len(z).
    """
    n, m, na = a.shape[0], u.shape[0], r.shape[0]
    N = n + na
    for i in range(n):  # F = ∂f/∂z; W[:, N] = f(z)
        acc = 0.0
        for j in range(n):
            F[i, j] = a[i, j]
            acc += a[i, j] * z[j]
        for j in range(m):
            acc += b[i, j] * u[j]
        W[i, N] = acc
    for k in range(na):
        delta = max(z[n + k], -0.9 * r[k])  # keep R + δ positive
        shift = dt * (1.0 / (r[k] + delta) - 1.0 / r[k])
        slope = -dt / (r[k] + delta) ** 2
        for i in range(n):
            flow = 0.0
            for j in range(n):
                flow += S[k, i, j] * z[j]
                F[i, j] += shift * S[k, i, j]
            for j in range(m):
                flow += T[k, i, j] * u[j]
            W[i, N] += shift * flow
            F[i, n + k] = slope * flow
        for i in range(N):
            F[n + k, i] = 0.0
        F[n + k, n + k] = 1.0
        W[n + k, N] = z[n + k]
    for i in range(N):  # W = F P
        z[i] = W[i, N]
        for j in range(N):
            acc = 0.0
            for l in range(N):
                acc += F[i, l] * P[l, j]
            W[i, j] = acc
    for i in range(N):  # P = W Fᵀ + Q
        for j in range(i + 1):
            acc = 0.0
            for l in range(N):
                acc += W[i, l] * F[j, l]
            if i < n:
                for k in range(q.shape[0]):
                    acc += b[i, m + k] * q[k] * b[j, m + k]
            elif i == j:
                acc += qd[i - n]
            P[i, j] = acc
            P[j, i] = acc


@njit(cache=True, nogil=True)
def reinitialise(z, P, state, value, variance):  # pragma: no cover - compiled
    """Set a state to a reading, its variance to the reading's, and forget its correlation with the others."""
    z[state] = value
    for j in range(z.shape[0]):
        P[state, j] = 0.0
        P[j, state] = 0.0
    P[state, state] = variance


@njit(cache=True, nogil=True)
def filter_run(op_index, Ad, Bd, inputs, q, resistances, S, T, qd, dt, readings, sensor_state, sensor_var,
               resets, reset_state, reset_var, z0, P0, out_z, out_std):  # pragma: no cover - compiled
    """Filter a whole run: at each sample re-initialise (`resets` not NaN), update with every reading that has a
    number, store the estimate and its standard deviation, then predict with the sample's inputs."""
    N = z0.shape[0]
    z, P = z0.copy(), P0.copy()
    gain, F, W = np.empty(N), np.empty((N, N)), np.empty((N, N + 1))
    for k in range(op_index.shape[0]):
        for r in range(resets.shape[1]):
            if not np.isnan(resets[k, r]):
                reinitialise(z, P, reset_state[r], resets[k, r], reset_var[r])
        for s in range(readings.shape[1]):
            if not np.isnan(readings[k, s]):
                update(z, P, sensor_state[s], readings[k, s], sensor_var[s], gain)
        for i in range(N):
            out_z[k, i] = z[i]
            out_std[k, i] = np.sqrt(max(P[i, i], 0.0))
        o = op_index[k]
        predict(Ad[o], Bd[o], inputs[k], q, resistances[k], S, T, qd, dt, z, P, F, W)


@njit(cache=True, nogil=True)
def filter_step(ab, u, q, r, S, T, qd, dt, readings, sensor_state, sensor_var, z, P, estimate,
                scratch):  # pragma: no cover - compiled
    """One online sample: update the carried prediction (z, P) with the readings that have a number, write the
    estimate at this sample and its standard deviations into `estimate` (2, N), predict (z, P) to the next
    sample. `ab` = [Ad | Bd] of this sample's operating point; `scratch` is (N, 2N + 2)."""
    N, n = z.shape[0], ab.shape[0]
    gain, F, W = scratch[:, 0], scratch[:, 1:N + 1], scratch[:, N + 1:]
    for s in range(readings.shape[0]):
        if not np.isnan(readings[s]):
            update(z, P, sensor_state[s], readings[s], sensor_var[s], gain)
    for i in range(N):
        estimate[0, i] = z[i]
        estimate[1, i] = np.sqrt(max(P[i, i], 0.0))
    predict(ab[:, :n], ab[:, n:], u, q, r, S, T, qd, dt, z, P, F, W)
