"""How a fit's scores Jᵀe respond to a change of the inputs: one backward (adjoint) pass per parameter.

The states are linear in the inputs while the operating points (the laws' values) stay as they are, so the
change e of the fitted outputs that an input change du causes is the network driven by du alone from a zero
state, and the score Jᵀe is Σₖ gₖ·duₖ with the gains g of the adjoint recursion λₖ = wₖ + Adₖᵀ λₖ₊₁,
gₖ = Bdₖᵀ λₖ₊₁ (wₖ: the Jacobian's entries of sample k). One backward pass per parameter replaces one simulation
per input change: the input-noise Monte Carlo of benchlab.identify.uncertainty evaluates its draws through it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numba import njit

from benchlab.identify.data import FitData
from benchlab.identify.fit import KEY_RESOLUTION, run_values
from benchlab.network import Channels, ThermalNetwork, as_samples, sample_matrix
from benchlab.network.solver import _coefficients, _conductances, discretise


class ScoreResponse:
    """The scores Jᵀe of one run's fitted samples (`jacobian`: that run's rows of the fit's Jacobian, in
    `residual_vector`'s order) as a function of the run's channels, at the parameters `params`."""

    def __init__(self, network: ThermalNetwork, params: Mapping[str, float], data: FitData,
                 jacobian: np.ndarray) -> None:
        self.network, self.data = network, data
        self.values = run_values(params, data)
        self.samples = len(data)
        disc = discretise(network, self.values, data.channels, data.dt, KEY_RESOLUTION, data.memo)
        self.laws = self._laws(data.channels)
        self.inputs = disc.inputs[: self.samples]
        flat, _ = data.fitted_flat(network.state_names, network.outputs)
        states = len(network.state_names)
        weights = np.stack([np.bincount(flat, weights=column, minlength=states * (self.samples + 1))
                            for column in np.asarray(jacobian, dtype=np.float64).T]).reshape(-1, states,
                                                                                              self.samples + 1)
        gains = np.empty((len(weights), self.samples, self.inputs.shape[1]))
        _adjoint_gains(disc.op_index[: self.samples], disc.Ad, disc.Bd, weights, gains)
        self.gains = gains.reshape(len(weights), -1)

    def _laws(self, channels: Channels) -> list:
        return (_conductances(self.network, self.values, channels, self.samples)
                + _coefficients(self.network, self.values, channels))

    def score(self, channels: Channels) -> np.ndarray | None:
        """Jᵀe for the run driven by `channels` instead of its own; None where they move an operating point (a law
        reads a changed channel: the states are then not linear in the change, and the caller simulates)."""
        if not all(_same(a, b) for a, b in zip(self.laws, self._laws(channels))):
            return None
        columns = [as_samples(s.heat_flow(self.values, channels), self.samples) for s in self.network.sources]
        columns += [as_samples(b.temperature(channels), self.samples) for b in self.network.boundaries]
        change = sample_matrix(columns, self.samples) - self.inputs
        return self.gains @ change.ravel()


def _same(a: "np.ndarray | float", b: "np.ndarray | float") -> bool:
    """Whether two law values are equal bit for bit (NaN never occurs: the solver checks them finite)."""
    return np.array_equal(a, b) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else a == b


@njit(cache=True, nogil=True)
def _adjoint_gains(op_index, Ad, Bd, weights, gains):  # pragma: no cover - compiled
    """gains[j, k] = Bdₖᵀ λₖ₊₁ with λₖ = weights[j, :, k] + Adₖᵀ λₖ₊₁ and λ after the last sample zero: d score j
    / d input at sample k, the states at sample k depending on the inputs before it (weights: state-major)."""
    p, n = weights.shape[0], weights.shape[1]
    samples = gains.shape[1]
    m = Bd.shape[2]
    lam = np.zeros(n)
    nxt = np.empty(n)
    for j in range(p):
        lam[:] = 0.0
        for k in range(samples - 1, -1, -1):
            o = op_index[k]
            for c in range(m):
                acc = 0.0
                for i in range(n):
                    acc += Bd[o, i, c] * lam[i]
                gains[j, k, c] = acc
            for i in range(n):
                acc = weights[j, i, k]
                for l in range(n):
                    acc += Ad[o, l, i] * lam[l]
                nxt[i] = acc
            lam[:] = nxt
