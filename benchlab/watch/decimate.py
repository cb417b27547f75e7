"""Min/max decimation: each channel's smallest and largest value per bucket of 2**level grid rows.

A plot drawn from one bucket per pixel (a vertical stroke from min to max) looks like the plot of every sample,
spikes included, however many samples the bucket holds. The pyramid keeps the buckets of every level from
`base_level` up and brings them up to date from the rows that arrived, so an update costs what arrived (times
the few levels), not the length of the run. A level is brought up to date when it is asked for (from the level
below, from the first bucket that changed), so an update touches the levels up to the one the page shows.
Finer buckets than the base level are computed from the rows when asked for.
NaN (not measured) is skipped; a bucket without any measured sample is NaN.
"""

from __future__ import annotations

import numpy as np

#: Levels kept: buckets of 2**7 = 128 rows (1.28 s at 10 ms) up to 2**26 rows (7.8 days at 10 ms).
BASE_LEVEL = 7
TOP_LEVEL = 26


def bucket_reduce(values: np.ndarray, size: int, ufunc: np.ufunc) -> np.ndarray:
    """`ufunc` (np.fmin or np.fmax) over consecutive buckets of `size` along the last axis (the last may be short)."""
    n = values.shape[-1]
    buckets = -(-n // size)
    if buckets == 0:
        return np.empty((*values.shape[:-1], 0), dtype=values.dtype)
    if buckets * size != n:
        pad = np.full((*values.shape[:-1], buckets * size - n), np.nan, dtype=values.dtype)
        values = np.concatenate([values, pad], axis=-1)
    return ufunc.reduce(values.reshape(*values.shape[:-1], buckets, size), axis=-1)


def _pairs(values: np.ndarray, ufunc: np.ufunc) -> np.ndarray:
    """`ufunc` of consecutive pairs along the last axis (an odd last one stays as it is)."""
    n = values.shape[-1]
    pairs = ufunc(values[:, 0:n - 1:2], values[:, 1:n:2])
    return np.concatenate([pairs, values[:, n - 1:]], axis=1) if n % 2 else pairs


def minmax(values: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Min and max per bucket of `size` rows of `values` (channels, rows), as float32."""
    return (bucket_reduce(values, size, np.fmin).astype(np.float32),
            bucket_reduce(values, size, np.fmax).astype(np.float32))


class _Level:
    """Buckets of one size for all channels: min and max arrays that grow by doubling."""

    def __init__(self, channels: int) -> None:
        self.min = np.full((channels, 64), np.nan, np.float32)
        self.max = np.full((channels, 64), np.nan, np.float32)
        self.count = 0  # buckets holding data (the last one may still fill)

    def store(self, first: int, mins: np.ndarray, maxs: np.ndarray) -> None:
        end = first + mins.shape[1]
        if end > self.min.shape[1]:
            grow = max(end, 2 * self.min.shape[1]) - self.min.shape[1]
            pad = np.full((self.min.shape[0], grow), np.nan, np.float32)
            self.min, self.max = np.concatenate([self.min, pad], 1), np.concatenate([self.max, pad], 1)
        self.min[:, first:end], self.max[:, first:end] = mins, maxs
        self.count = max(self.count, end)


class MinMaxPyramid:
    """Min/max buckets of 2**level rows for every level in [BASE_LEVEL, TOP_LEVEL], kept up to date incrementally."""

    def __init__(self, channels: int) -> None:
        self.channels = channels
        self.levels = [_Level(channels) for _ in range(BASE_LEVEL, TOP_LEVEL + 1)]
        self._stale = [0] * len(self.levels)  # per level: its buckets from here on may be out of date

    def ingest(self, first_row: int, values: np.ndarray) -> None:
        """Rows `first_row`, ... of every channel (channels, rows); `first_row` starts a base bucket.

        The caller passes again the rows of a base bucket that was still filling, so it is computed whole.
        """
        size = 1 << BASE_LEVEL
        if first_row % size:
            raise ValueError(f"rows must start on a bucket of {size} rows, got row {first_row}")
        if values.shape[1] == 0:
            return
        first = first_row // size
        mins, maxs = minmax(values, size)
        self.levels[0].store(first, mins, maxs)
        for j in range(1, len(self.levels)):
            self._stale[j] = min(self._stale[j], first >> j)

    def _bring_up_to_date(self, index: int) -> None:
        """Levels 1..index (above the base) recomputed from the level below, from their first stale bucket."""
        for j in range(1, index + 1):
            below, level, first = self.levels[j - 1], self.levels[j], self._stale[j]
            if first < -(-below.count // 2):
                level.store(first, _pairs(below.min[:, 2 * first:below.count], np.fmin),
                            _pairs(below.max[:, 2 * first:below.count], np.fmax))
            self._stale[j] = level.count

    def buckets(self, level: int, first: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Min and max of buckets [first, stop) at `level` (BASE_LEVEL..TOP_LEVEL), clipped to the buckets held."""
        if not BASE_LEVEL <= level <= TOP_LEVEL:
            raise ValueError(f"level {level} outside [{BASE_LEVEL}, {TOP_LEVEL}]")
        self._bring_up_to_date(level - BASE_LEVEL)
        held = self.levels[level - BASE_LEVEL]
        stop = min(stop, held.count)
        first = min(max(first, 0), stop)
        return held.min[:, first:stop], held.max[:, first:stop]
