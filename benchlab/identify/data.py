"""Runs made ready for fitting: inputs block-averaged to a coarser step, targets at the block starts.

The fastest thermal dynamics (heating while slipping) take about 2 s, so a 0.5 s fitting step
loses nothing a 10 ms record carries; friction power is averaged per block, which keeps the
energy exact. Operating-point channels (speeds, clutch state) are rounded so that identical
operating points share one matrix exponential for every trial parameter set, which keeps
finite-difference derivatives smooth. NaN targets stay NaN: drop-outs are skipped, not filled.

A window mean equals the point temperature only where the temperature is smooth in the window.
While slipping the flywheel heats at up to about 1 K/s with a kink at each slip start and end,
and there the mean of a 1 s window is off by up to 0.2 K: a bias that no parameter can fit and
that spurious extensions then mop up. Flywheel targets whose window holds slipping are skipped
(about 8 % of samples at a 1 s step); the heat shows in the samples after the slip, where the
flywheel is smooth again. Measured on a noise-free 1 h run: 0.0088 K of bias at 1 s, 0.0007 K left.

A reading counts on the grid from the time it was measured until the next one (docs/runfile.md, hold rule),
so a grid value is on average half a reading period old: 25 ms for the node, 0.25 s for a scanner read every
0.5 s. The temperatures rise and fall through every engagement, and that age biased the capacities by up to
1.7 standard errors (C_P, C_A on the drivers' runs, benchmarks/coverage_study.py). Each target's window is therefore
centred on the block start plus its readings' mean age, (hold − 1)/2 samples, the hold measured from the data
itself (`hold_samples`: the common length of runs of repeated values; 1, no shift, for a channel that changes
every sample or whose runs are quantisation plateaus of varying length).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import pandas as pd

from benchlab.identify.defaults import FIT_STEP_S
from benchlab.network import ThermalNetwork
from benchlab.runfile import ALIGNED_UNITS
from benchlab.network.simulation import input_channels
from benchlab.network.memo import LawMemo

#: Operating-point quantum per unit of a channel: speeds to 0.5 rpm, temperatures read by laws to 0.1 K.
QUANTUM = {"rpm": 0.5, "degC": 0.1}
STATE_CHANNEL = "clutch_state"  # 0 or 1: rounded
INITIAL_WINDOW_S = 10.0
SLIP_POWER = "friction_power"  # the clutch's heat input: its slip windows are skipped in the targets it heats
SLIP_HEATED_CHANNELS = ("T_flywheel",)  # heated by P directly: kinks at slip start and end


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
    units: dict[str, str] = field(default_factory=dict)  # channel -> unit, as the run file gives it
    #: the run's group for parameters fitted per group (`X@<group>`, benchlab.identify.fit.run_values); its name
    #: where empty (every run its own group)
    group: str = ""
    #: the solver's memo of these channels, which are never changed after prepare (shared by with_mask's copies)
    memo: LawMemo = field(default_factory=LawMemo, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.mask)

    @cached_property
    def fitted(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per target channel: the samples that count in the fit (masked in, target valid) and their targets."""
        out = {}
        for c, target in self.targets.items():
            index = np.flatnonzero(self.mask & np.isfinite(target))
            out[c] = (index, target[index])
        return out

    def fitted_flat(self, states: list[str], outputs: Mapping[str, str]) -> tuple[np.ndarray, np.ndarray]:
        """The fitted samples (`fitted`, channel after channel) as indices into the raveled state-major states
        (`states` × the run's samples + 1: the solver's own layout, read without a copy) of a model that outputs
        each channel from the state `outputs` names, and their targets."""
        key = (tuple(states), tuple(outputs[c] for c in self.targets))
        found = self._flat.get(key)
        if found is None:
            row = {s: i * (len(self) + 1) for i, s in enumerate(states)}
            flat = [row[outputs[c]] + index for c, (index, _) in self.fitted.items()]
            targets = [target for index, target in self.fitted.values()]
            found = self._flat[key] = ((np.concatenate(flat), np.concatenate(targets)) if flat else
                                       (np.zeros(0, dtype=np.int64), np.zeros(0)))
        return found

    @cached_property
    def _flat(self) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
        return {}

    @property
    def group_label(self) -> str:
        """The label of this run's per-group parameters: its group, else its name."""
        return self.group or self.name

    def with_mask(self, mask: np.ndarray) -> "FitData":
        return replace(self, mask=mask)


def _block_mean(values: np.ndarray, block: int) -> np.ndarray:
    n = len(values) // block
    return values[: n * block].reshape(n, block).mean(axis=1)


def _centred_windows(values: np.ndarray, block: int, n_blocks: int) -> np.ndarray:
    """(n_blocks, block) windows of `block` samples centred on each block start, NaN beyond the run."""
    half = block // 2
    padded = np.concatenate([np.full(half, np.nan), values, np.full(block, np.nan)])
    return padded[: n_blocks * block].reshape(n_blocks, block)


def _centred_mean(values: np.ndarray, block: int, n_blocks: int) -> np.ndarray:
    """Mean of the measured values in a window of `block` samples centred on each block start."""
    windows = _centred_windows(values, block, n_blocks)
    measured = np.isfinite(windows)
    count = measured.sum(axis=1)
    # not np.nanmean under warnings.catch_warnings: that filter is process-wide state, not safe in dask's threads
    out = np.where(measured, windows, 0.0).sum(axis=1) / np.maximum(count, 1)
    out[count < max(1, block // 4)] = np.nan
    return out


def hold_samples(values: np.ndarray) -> int:
    """Grid samples one reading is held for: the length most runs of equal consecutive measured values share (a
    sensor read at a fixed period); 1 where no length holds half of them (a slow signal's quantisation plateaus
    vary in length and are not holds)."""
    valid = values[np.isfinite(values)]
    lengths = np.diff(np.flatnonzero(np.diff(valid) != 0))
    if not lengths.size:
        return 1
    common = _median_count(lengths)
    return common if np.mean(lengths == common) >= 0.5 else 1


def _median_count(lengths: np.ndarray) -> int:
    """int(np.median(lengths)) of positive integers, from their histogram: one pass instead of a partial sort of a
    run-long array (each 10 ms sample of a noisy channel is a run of length 1)."""
    cumulative = np.cumsum(np.bincount(lengths))
    n = lengths.size
    lower, upper = np.searchsorted(cumulative, [(n - 1) // 2 + 1, n // 2 + 1])
    return int((int(lower) + int(upper)) / 2)


def _aged(values: np.ndarray) -> np.ndarray:
    """The values moved earlier by their readings' mean age, (hold − 1)/2 samples (NaN at the end)."""
    shift = int(round((hold_samples(values) - 1) / 2))
    return np.concatenate([values[shift:], np.full(shift, np.nan)]) if shift else values


def _slip_windows(friction_power: np.ndarray, block: int, n_blocks: int) -> np.ndarray:
    """True where a target's averaging window holds slipping (or is cut by the run's start)."""
    windows = _centred_windows(np.where(np.isnan(friction_power), 0.0, friction_power), block, n_blocks)
    return np.any(windows > 0, axis=1) | np.any(np.isnan(windows[:, : block // 2]), axis=1)


def _initial_values(full: dict[str, np.ndarray], dt: float) -> dict[str, float]:
    """Each channel's value at t = 0: the intercept of a straight line through its valid samples of the first
    INITIAL_WINDOW_S (for the flywheel: before the first slip), or its first valid sample where there are
    fewer than two.

    One reading carries the sensor's full noise (0.03–0.08 K), and an initial error in the housing
    decays over its hour-long time constant: the fit then bends parameters by several % to absorb it.
    """
    slipping = full[SLIP_POWER] > 0 if SLIP_POWER in full else np.zeros(1, dtype=bool)
    first_slip = int(np.argmax(slipping)) if slipping.any() else len(next(iter(full.values())))
    window = int(INITIAL_WINDOW_S / dt)
    out = {}
    for c, values in full.items():
        early = np.flatnonzero(np.isfinite(values[: min(window, first_slip) if c.startswith(SLIP_HEATED_CHANNELS)
                                                   else window]))
        if early.size >= 2 and np.ptp(early) > 0:
            out[c] = float(np.polyval(np.polyfit(early * dt, values[early], 1), 0.0))
            continue
        valid = np.isfinite(values)
        if valid.any():
            out[c] = float(values[int(np.argmax(valid))])
    return out


def _quantised(channels: dict[str, np.ndarray], units: dict[str, str], measured: tuple[str, ...]) -> None:
    """Round operating-point channels so that equal operating points share one matrix exponential for every
    trial parameter set (smooth finite differences): speeds (rpm) and measured temperatures (as law signals)
    to their QUANTUM, the clutch state to 0 or 1. Other channels (powers, boundary temperatures) stay exact."""
    for key, values in channels.items():
        unit = units.get(key, "")
        if key == STATE_CHANNEL:
            channels[key] = np.round(values)
        elif unit == "rpm" or (unit == "degC" and key in measured):
            channels[key] = np.round(values / QUANTUM[unit]) * QUANTUM[unit]


def prepare(run: pd.DataFrame, step_s: float = FIT_STEP_S, name: str | None = None,
            network: ThermalNetwork | None = None) -> FitData:
    """Decimate a run for fitting (block mean of inputs, centred means of measured temperatures).

    `network`: the model whose measured outputs are the targets (default: the paper's clutch).
    """
    if network is None:
        from benchlab.model.clutch import clutch_network

        network = clutch_network()
    dt = float(run.attrs["dt"])
    block = max(1, int(round(step_s / dt)))
    full = input_channels(run)
    raw = {c: run[c].to_numpy(np.float64) for c in network.measured if c in run.columns}
    n_blocks = len(run) // block
    channels = {k: _block_mean(v, block) for k, v in full.items() if np.issubdtype(v.dtype, np.number)}
    units = {k: u for k, u in {**ALIGNED_UNITS, **run.attrs.get("units", {})}.items() if k in channels}
    _quantised(channels, units, network.measured)
    targets = {c: _centred_mean(_aged(values), block, n_blocks) for c, values in raw.items()}
    if block > 1 and SLIP_POWER in full:
        kinked = _slip_windows(full[SLIP_POWER], block, n_blocks)
        for c in SLIP_HEATED_CHANNELS:
            if c in targets:
                targets[c][kinked] = np.nan
    first_valid = _initial_values({**{k: v for k, v in full.items() if k not in raw}, **raw}, dt)
    return FitData(name or str(run.attrs.get("source", "run")), dt * block, channels, targets, first_valid, block,
                   np.ones(n_blocks, dtype=bool), units)


def scout_runs(data: FitData, coarser: int = 4, every: int = 2) -> FitData:
    """A cheaper version of a prepared run for a search's scouts (benchlab.identify.fit.fit_multistart): inputs
    averaged over `coarser` fitting steps (quantised again), targets those of every `coarser` × `every`-th step.

    Not what `prepare` gives at that step (the targets keep their windows, the slip windows skipped are the fitting
    step's): a nearby problem with the same minima, each a little apart from the run's own, which the search only
    has to tell apart; its polish then fits the run itself. On a 2 h Table 1 run (0.5 s fitting step) the search
    with its polish cost 0.30 s of CPU with the scouts at 2 s and every 4 s, 0.41 s at 1 s and every 2 s, 0.48 s on
    every 4th step of the run itself, 1.19 s on all of it; every one ended at the same minimum.
    """
    n = len(data) // coarser
    channels = {name: _block_mean(values, coarser) for name, values in data.channels.items()}
    _quantised(channels, data.units, tuple(data.targets))
    picked = (np.arange(n) % every == 0) & data.mask[: n * coarser: coarser]
    return FitData(data.name, data.dt * coarser, channels,
                   {c: target[: n * coarser: coarser].copy() for c, target in data.targets.items()},
                   data.first_valid, data.block * coarser, picked, data.units, data.group)
