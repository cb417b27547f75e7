"""Source channels, each at its own time stamps, onto one uniform grid, by a stated rule per channel.

`hold`: the last sample at or before a grid point (states, set-points: `clutch_state`, an enum, a counter).
`interpolate`: linear between the samples either side (temperatures, speeds, torques). Neither bridges a gap: a
sample is held for at most GAP_SAMPLES of the channel's median sample period, and only samples at most that far
apart are interpolated between; the rest of a longer gap stays NaN, and so does the grid before a channel's first
sample. A NaN sample (an
invalidation bit) is not measured: held, it stays NaN; interpolated, the grid points beside it are NaN.
"""

from __future__ import annotations

import numpy as np

#: The longest gap between two samples that still gives values, in the channel's median sample periods.
GAP_SAMPLES = 3.0


def resample(stamps: np.ndarray, values: np.ndarray, grid: np.ndarray, rule: str) -> np.ndarray:
    """`values` at `stamps` (any order, NaN stamps dropped) at the times `grid` by `rule` (hold, interpolate)."""
    keep = np.isfinite(stamps)
    order = np.argsort(stamps[keep], kind="stable")
    t, v = stamps[keep][order], np.asarray(values, dtype=np.float64)[keep][order]
    out = np.full(len(grid), np.nan)
    if len(t) == 0:
        return out
    max_gap = GAP_SAMPLES * float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    prev = np.searchsorted(t, grid, side="right") - 1
    seen = prev >= 0
    p = np.where(seen, prev, 0)
    if rule == "hold":
        ok = seen & (grid - t[p] <= max_gap)
        out[ok] = v[p[ok]]
        return out
    exact = seen & (t[p] == grid)
    n = np.minimum(p + 1, len(t) - 1)
    span = t[n] - t[p]
    between = seen & ~exact & (n > p) & (span <= max_gap)
    out[exact] = v[p[exact]]
    w = (grid[between] - t[p[between]]) / span[between]
    out[between] = v[p[between]] + w * (v[n[between]] - v[p[between]])
    return out
