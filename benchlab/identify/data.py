"""Runs made ready for fitting: inputs block-averaged to a coarser step, targets at the block starts.

The fastest thermal dynamics (heating while slipping) take about 2 s, so a 0.5 s fitting step
loses nothing a 10 ms record carries; friction power is averaged per block, which keeps the
energy exact. Operating-point channels (speeds, clutch state) are rounded so that identical
operating points share one matrix exponential for every trial parameter set, which keeps
finite-difference derivatives smooth. NaN targets stay NaN: drop-outs are skipped, not filled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.clutch import PREDICTED_CHANNELS
from benchlab.simulation import input_channels

FIT_STEP_S = 0.5
SPEED_QUANTUM_RPM = 0.5
TEMPERATURE_QUANTUM_K = 0.1
OPERATING_CHANNELS = ("engine_speed", "clutch_speed")


@dataclass
class FitData:
    """One run at the fitting step: channels for the network's laws, targets, first valid temperatures."""

    name: str
    dt: float
    channels: dict[str, np.ndarray]
    targets: dict[str, np.ndarray]  # measured channel -> values at block starts (NaN where missing)
    first_valid: dict[str, float]
    block: int
    mask: np.ndarray  # True where the sample counts in the fit

    def __len__(self) -> int:
        return len(self.mask)

    def with_mask(self, mask: np.ndarray) -> "FitData":
        return FitData(self.name, self.dt, self.channels, self.targets, self.first_valid, self.block, mask)


def _block_mean(values: np.ndarray, block: int) -> np.ndarray:
    n = len(values) // block
    return values[: n * block].reshape(n, block).mean(axis=1)


def _centred_mean(values: np.ndarray, block: int, n_blocks: int) -> np.ndarray:
    """Mean of the measured values in a window of `block` samples centred on each block start."""
    half = block // 2
    padded = np.concatenate([np.full(half, np.nan), values, np.full(block, np.nan)])
    windows = padded[: (n_blocks) * block].reshape(n_blocks, block)
    with np.errstate(invalid="ignore"), np.testing.suppress_warnings() as sup:
        sup.filter(RuntimeWarning)
        out = np.nanmean(windows, axis=1)
    out[np.sum(np.isfinite(windows), axis=1) < max(1, block // 4)] = np.nan
    return out


def prepare(run: pd.DataFrame, step_s: float = FIT_STEP_S, name: str | None = None) -> FitData:
    """Decimate a run for fitting (block mean of inputs, centred means of measured temperatures)."""
    dt = float(run.attrs["dt"])
    block = max(1, int(round(step_s / dt)))
    full = input_channels(run)
    n_blocks = len(run) // block
    channels = {k: _block_mean(v, block) for k, v in full.items() if np.issubdtype(v.dtype, np.number)}
    for key in OPERATING_CHANNELS:
        if key in channels:
            channels[key] = np.round(channels[key] / SPEED_QUANTUM_RPM) * SPEED_QUANTUM_RPM
    channels["clutch_state"] = np.round(channels["clutch_state"])
    for key in [k for k in channels if k.endswith("_filled")]:  # temperatures as law signals: 0.1 K steps
        channels[key] = np.round(channels[key] / TEMPERATURE_QUANTUM_K) * TEMPERATURE_QUANTUM_K
    measured = [c for c in PREDICTED_CHANNELS if c in full]
    targets = {c: _centred_mean(full[c], block, n_blocks) for c in measured}
    first_valid = {}
    for c, values in full.items():
        valid = np.flatnonzero(np.isfinite(values))
        if valid.size:
            first_valid[c] = float(values[valid[0]])
    return FitData(name or str(run.attrs.get("source", "run")), dt * block, channels, targets, first_valid, block,
                   np.ones(n_blocks, dtype=bool))
