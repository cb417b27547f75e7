"""Remaining life by Monte Carlo: future engagements resampled from the run's own (energy, temperature) load.

Each path draws past engagements with replacement (from its own bootstrap of them), adds their wear and
μ-loss increments to the current state and stops at the first engagement after which the clutch is worn.
Percentiles of the engagements (and operating hours, from each drawn engagement's cycle time) to that
point form the distribution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.health import worn
from benchlab.wear.state import WearState

STATE_FIELDS = ("wear_plate_mm", "wear_flywheel_mm", "loss_plate", "loss_flywheel")
PERCENTILES = (10, 50, 90)
#: Paths still intact after this many times the mean-load life are reported as censored (beyond the horizon searched).
SEARCH_FACTOR = 4
MAX_SEARCH = 10 ** 8


@dataclass(frozen=True)
class LifeDistribution:
    """Remaining engagements and hours until worn over Monte Carlo paths; inf marks a censored path."""

    engagements: np.ndarray
    hours: np.ndarray
    horizon_engagements: int
    searched_engagements: int
    seed: int

    def percentiles(self, values: np.ndarray) -> dict[str, float | None]:
        """P10/P50/P90 as drawn samples (None where the percentile lies among censored paths)."""
        out = {}
        for p in PERCENTILES:
            q = float(np.quantile(values, p / 100.0, method="inverted_cdf")) if len(values) else np.inf
            out[f"p{p}"] = q if np.isfinite(q) else None
        return out

    @property
    def p_fail_within_horizon(self) -> float:
        return float(np.mean(self.engagements <= self.horizon_engagements))

    def as_dict(self) -> dict[str, object]:
        return {"paths": int(len(self.engagements)), "seed": self.seed,
                "horizon_engagements": self.horizon_engagements,
                "p_fail_within_horizon": self.p_fail_within_horizon,
                "engagements": self.percentiles(self.engagements), "hours": self.percentiles(self.hours),
                "censored_fraction": float(np.mean(~np.isfinite(self.engagements))),
                "searched_engagements": self.searched_engagements}


def _worn_rows(spec: ClutchSpec, states: np.ndarray) -> np.ndarray:
    return worn(spec, states[..., 0], states[..., 1], states[..., 2], states[..., 3])


def mean_load_life(spec: ClutchSpec, state: WearState, mean_increment: np.ndarray) -> int | None:
    """Engagements until worn if every engagement brought the mean increment; None if never (within MAX_SEARCH)."""
    start = np.array([getattr(state, name) for name in STATE_FIELDS])
    if _worn_rows(spec, start[None, :])[0]:
        return 0
    hi = 1
    while not _worn_rows(spec, (start + hi * mean_increment)[None, :])[0]:
        hi *= 2
        if hi > MAX_SEARCH:
            return None
    lo = hi // 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if _worn_rows(spec, (start + mid * mean_increment)[None, :])[0] else (mid, hi)
    return hi


def _first_failure(spec: ClutchSpec, base: np.ndarray, counts: np.ndarray, increments: np.ndarray,
                   cycle_s: np.ndarray, rng: np.random.Generator) -> tuple[int, float]:
    """Order a chunk's drawn engagements at random and find the first after which the clutch is worn."""
    order = rng.permutation(np.repeat(np.arange(len(counts)), counts))
    states = base + np.cumsum(increments[order], axis=0)
    first = int(np.argmax(_worn_rows(spec, states)))
    return first + 1, float(np.sum(cycle_s[order[:first + 1]]))


def remaining_life(spec: ClutchSpec, state: WearState, increments: np.ndarray, cycle_s: np.ndarray,
                   horizon: int, paths: int = 500, seed: int = 0, chunk: int = 4096) -> LifeDistribution:
    """Monte Carlo life from `state`: `increments` (n, 4) per past engagement in STATE_FIELDS order, `cycle_s` (n,).

    Two-level bootstrap: each path first resamples the run's n engagements into its own load profile
    (the uncertainty of a scenario known from n engagements only), then draws its future engagements
    from that profile, a chunk at a time as multinomial counts. Worn is taken as absorbing, so the
    engagement-by-engagement search runs only inside the chunk at whose end a path is first worn.
    """
    start = np.array([getattr(state, name) for name in STATE_FIELDS])
    life = np.full(paths, np.inf)
    hours = np.full(paths, np.inf)
    n = len(increments)
    mean_life = mean_load_life(spec, state, increments.mean(axis=0)) if n else None
    if mean_life == 0:
        return LifeDistribution(np.zeros(paths), np.zeros(paths), horizon, 0, seed)
    if mean_life is None:
        return LifeDistribution(life, hours, horizon, 0, seed)
    search = max(horizon, SEARCH_FACTOR * mean_life)
    rng = np.random.default_rng(seed)
    profiles = rng.multinomial(n, np.full(n, 1.0 / n), size=paths) / n
    alive = np.arange(paths)
    base = np.tile(start, (paths, 1))
    base_seconds = np.zeros(paths)
    done = 0
    while len(alive) and done < search:
        m = min(chunk, search - done)
        counts = rng.multinomial(m, profiles[alive])
        ends = base[alive] + counts @ increments
        hit = _worn_rows(spec, ends)
        for row in np.flatnonzero(hit):
            path = alive[row]
            used, seconds = _first_failure(spec, base[path], counts[row], increments, cycle_s, rng)
            life[path], hours[path] = done + used, (base_seconds[path] + seconds) / 3600.0
        base[alive], base_seconds[alive] = ends, base_seconds[alive] + counts @ cycle_s
        alive = alive[~hit]
        done += m
    return LifeDistribution(life, hours, horizon, search, seed)
