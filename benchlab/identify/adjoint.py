"""How a fit's scores Jᵀe respond to a change of the inputs: one backward (adjoint) pass per parameter.

The states are linear in the inputs while the operating points (the laws' values) stay as they are, so the
change e of the fitted outputs that an input change du causes is the network driven by du alone from a zero
state, and the score Jᵀe is Σₖ gₖ·duₖ with the gains g of the adjoint recursion λₖ = wₖ + Adₖᵀ λₖ₊₁,
gₖ = Bdₖᵀ λₖ₊₁ (wₖ: the Jacobian's entries of sample k). One backward pass per parameter replaces one simulation
per input change: the input-noise Monte Carlo of benchlab.identify.uncertainty evaluates its draws through it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np
from benchlab.jit import njit

from benchlab.identify.data import FitData
from benchlab.identify.fit import KEY_RESOLUTION, reading_gains, run_values
from benchlab.network import Channels, ThermalNetwork, as_samples
from benchlab.network.solver import discretise, matrix_laws


class ScoreResponse:
    """The scores Jᵀe of one run's fitted samples (`jacobian`: that run's rows of the fit's Jacobian, in
    `residual_vector`'s order) as a function of the run's channels, at the parameters `params`."""

    def __init__(self, network: ThermalNetwork, params: Mapping[str, float], data: FitData,
                 jacobian: np.ndarray) -> None:
        self.network, self.data = network, data
        self.values = run_values(params, data)
        self.samples = len(data)
        disc = discretise(network, self.values, data.channels, data.dt, KEY_RESOLUTION, data.memo)
        reads = _Reads(data.channels)
        self.laws = self._laws(reads)
        self.law_channels = None if reads.listed else frozenset(reads.names)  # None: any channel may be read
        self.inputs = disc.inputs[: self.samples]
        flat, _ = data.fitted_flat(network.state_names, network.outputs)
        gains = reading_gains(network, params, data)  # a calibrated sensor reads its state times its gain
        jacobian = np.asarray(jacobian, dtype=np.float64) if gains is None else jacobian * gains[:, None]
        states = len(network.state_names)
        weights = np.stack([np.bincount(flat, weights=column, minlength=states * (self.samples + 1))
                            for column in np.asarray(jacobian, dtype=np.float64).T]).reshape(-1, states,
                                                                                              self.samples + 1)
        gains = np.empty((len(weights), self.samples, self.inputs.shape[1]))
        _adjoint_gains(disc.op_index[: self.samples], disc.Ad, disc.Bd, weights, gains)
        self.gains = gains.reshape(len(weights), -1)
        self._changes = np.empty((0, self.gains.shape[1]))

    def _laws(self, channels: Channels) -> list:
        """The laws the operating points are made of (conductances, source coefficients, capacities) on `channels`."""
        return matrix_laws(self.network, self.values, channels, self.samples)[0]

    def scores(self, draws: Sequence[Channels]) -> list[np.ndarray | None]:
        """Jᵀe for the run driven by each of `draws` (channels) instead of its own; None where they move an operating
        point (a law reads a changed channel and its value changes: the states are then not linear in the change,
        and the caller simulates)."""
        if len(self._changes) < len(draws):  # one buffer for every batch: no fresh run-sized mapping per batch
            self._changes = np.empty((len(draws), self.gains.shape[1]))
        out, used = [], 0
        for channels in draws:
            if not self._same_points(channels):
                out.append(None)
                continue
            change = self._changes[used].reshape(self.inputs.shape)
            columns = [as_samples(s.heat_flow(self.values, channels), self.samples) for s in self.network.sources]
            columns += [as_samples(b.temperature(channels), self.samples) for b in self.network.boundaries]
            for j, column in enumerate(columns):
                np.subtract(column, self.inputs[:, j], out=change[:, j])
            out.append(used)
            used += 1
        together = self.gains @ self._changes[:used].T
        return [None if k is None else together[:, k] for k in out]

    def _same_points(self, channels: Channels) -> bool:
        """Whether the laws give the run's own values on `channels`: certainly where they read none of the channels
        that differ from the run's (as they did on the run's own), else checked by evaluating them."""
        own = self.data.channels
        changed = {name for name, values in channels.items() if own.get(name) is not values}
        if self.law_channels is not None and not changed & self.law_channels and own.keys() == channels.keys():
            return True
        return all(_same(a, b) for a, b in zip(self.laws, self._laws(channels)))


class _Reads(Mapping):
    """A run's channels that note the names a law reads (`listed`: it went through all of them)."""

    def __init__(self, channels: Channels) -> None:
        self.channels, self.names, self.listed = channels, set(), False

    def __getitem__(self, name: str) -> np.ndarray:
        self.names.add(name)
        return self.channels[name]

    def __contains__(self, name: object) -> bool:
        self.names.add(name)
        return name in self.channels

    def __iter__(self) -> Iterator[str]:
        self.listed = True
        return iter(self.channels)

    def __len__(self) -> int:
        self.listed = True
        return len(self.channels)


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
