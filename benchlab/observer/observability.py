"""Which states the chosen sensors make observable, over a run's operating points.

At each operating point the discrete model is (Ad, H): H selects the states the sensors read. The
observability matrix [H; H M; …; H Mⁿ⁻¹] with M = (Ad − I)/‖Ad − I‖ has the null space of the usual
[H; H Ad; …] (row operations by a polynomial in Ad) and is far better conditioned at a 10 ms step, where
Ad ≈ I. A state x_i is observable when the unit vector e_i lies in the row space, i.e. when no direction the
sensors cannot see moves it. The run's rank stacks the matrices of all its operating points (sampled evenly
in time when there are many); per state, the share of the run's time it is observable at the operating point
of the moment says where the estimate runs open loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: At most this many samples are looked at (evenly spaced in time): the share of time is a mean.
MAX_POINTS = 2000
#: Relative singular-value threshold for rank and null space.
RANK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Observability:
    """Rank over the run, per state whether it is observable, the share of time it is, and readings missing."""

    sensors: tuple[str, ...]
    states: tuple[str, ...]  # channel names of the states
    rank: int
    observable: dict[str, bool]
    time_share: dict[str, float]  # share of the run's samples at an operating point where the state is observable
    no_reading_share: float  # share of the run's samples where no chosen sensor has a number

    def warnings(self) -> list[str]:
        """One line per place where the estimate is open loop (the model alone, its band growing)."""
        out = []
        seen_from = ", ".join(self.sensors) if self.sensors else "no sensor"
        blind = [s for s in self.states if not self.observable[s]]
        if blind:
            out.append(f"not observable from {seen_from}: {', '.join(blind)}: the estimate is open loop "
                       "(the model alone, corrected by nothing)")
        partly = [f"{s} {100 * (1 - self.time_share[s]):.0f} %" for s in self.states
                  if self.observable[s] and self.time_share[s] < 0.999]
        if partly:
            out.append(f"open loop for part of the run (unobservable at the operating point of the moment): "
                       f"{', '.join(partly)} of the time")
        if self.sensors and self.no_reading_share >= 0.0005:  # what rounds to 0.0 % is not worth a warning
            out.append(f"no reading from {seen_from} for {100 * self.no_reading_share:.1f} % of the samples "
                       "(drop-outs): open loop there, the band widens")
        return out

    def as_dict(self) -> dict:
        return {"sensors": list(self.sensors), "rank": self.rank, "states": len(self.states),
                "observable": self.observable, "time_share": self.time_share,
                "no_reading_share": self.no_reading_share}


def _null_spaces(Ad: np.ndarray, sensor_state: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Observability matrices (K, n·s, n) of the operating points and the null space of each."""
    k, n = Ad.shape[0], Ad.shape[1]
    M = Ad - np.eye(n)
    scale = np.linalg.norm(M, ord=2, axis=(1, 2))
    M = M / np.where(scale > 0, scale, 1.0)[:, None, None]
    H = np.zeros((k, len(sensor_state), n))
    H[:, np.arange(len(sensor_state)), sensor_state] = 1.0
    blocks, row = [], H
    for _ in range(n):
        blocks.append(row)
        row = row @ M
    O = np.concatenate(blocks, axis=1)
    nulls = []
    if O.shape[1] == 0:
        return O, [np.eye(n)] * k
    _, sv, vt = np.linalg.svd(O)
    for i in range(k):
        rank = int(np.sum(sv[i] > RANK_TOLERANCE * max(sv[i][0], 1e-300)))
        nulls.append(vt[i, rank:].T)
    return O, nulls


def analyse(op_index: np.ndarray, Ad: np.ndarray, sensor_state: np.ndarray, readings: np.ndarray,
            sensors: tuple[str, ...], names: tuple[str, ...]) -> Observability:
    """Observability of the states `names` from sensors reading `sensor_state`, over the run's operating points."""
    n = Ad.shape[1]
    picks = np.unique(np.linspace(0, len(op_index) - 1, min(MAX_POINTS, len(op_index))).astype(np.int64))
    ops, inverse = np.unique(op_index[picks], return_inverse=True)
    O, nulls = _null_spaces(Ad[ops], np.asarray(sensor_state, dtype=np.int64))
    seen = np.array([[np.linalg.norm(null[i]) < 1e-6 if null.size else True for i in range(n)] for null in nulls])
    share = seen[inverse].mean(axis=0)
    stacked = O.reshape(-1, n)
    sv = np.linalg.svd(stacked, compute_uv=False) if stacked.size else np.zeros(0)
    rank = int(np.sum(sv > RANK_TOLERANCE * sv[0])) if sv.size and sv[0] > 0 else 0
    if rank == n:
        run_seen = np.ones(n, dtype=bool)
    elif rank == 0:
        run_seen = np.zeros(n, dtype=bool)
    else:
        _, _, vt = np.linalg.svd(stacked)
        null = vt[rank:].T
        run_seen = np.linalg.norm(null, axis=1) < 1e-6
    no_reading = float(np.mean(np.all(np.isnan(readings), axis=1))) if readings.shape[1] else 1.0
    return Observability(sensors, names, rank, {s: bool(v) for s, v in zip(names, run_seen)},
                         {s: float(v) for s, v in zip(names, share)}, no_reading)
