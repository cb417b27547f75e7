"""Why the model is wrong: which signal its held-out residuals depend on, with a test that survives autocorrelation.

Two forms of each measured channel's held-out residual are tested: its level (K) and its rate, the change
over RATE_S (K/min). A missing heat flow q(s) into a node of capacity C makes the residual change at
about −q(s)/C while it acts: where the node is slow (the housing) the level is the integral of that and
follows no instantaneous signal, but the rate does (a 40 W gearbox source on a 40-minute run: the housing's
rate residual 56 % explained by clutch speed, its level residual not significantly by anything).
For each signal, form and channel the statistic is the share of variance explained by the residual's
mean in bins of the signal (the correlation ratio η², in %). Residuals of a thermal model are
strongly autocorrelated and slow signals (time, temperatures) explain much of any slow residual by chance,
so the p-value compares the observed share with the shares obtained when the signal is circularly shifted
against the residual (each run by its own random offset, at least a tenth of the run): a shift keeps the
autocorrelation of both series and breaks only their alignment. Rows are ranked by p-value, then (where p
is at its floor, 1 / (SHIFTS + 1)) by the share beyond the shifted shares' median: the part of the residual
the signal accounts for beyond what autocorrelation alone gives.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import fft as sp_fft

from benchlab.diagnose.engine import BLOCK_S, FOLD_S, HeldOut
from benchlab.diagnose.library import signal_values
from benchlab.diagnose.regimes import time_since_slip
from benchlab.identify.data import FitData
from benchlab.identify.fit import KEY_RESOLUTION, initial_state
from benchlab.identify.spec import ModelSpec
from benchlab.network.solver import run_network

BINS = 10
SHIFTS = 999  # p-values from 1/1000 up; the FFT gives every shift, so more cost nothing
MIN_SHIFT_FRACTION = 0.1  # of the run's length: shorter shifts keep the signal nearly aligned with itself
DOMINANT_SHARE = 0.2  # a value held this often (0 rpm, 0 W) gets a bin of its own
MIN_BIN_SAMPLES = 10
RATE_S = 30.0
FORMS = {"level": "K", "rate": "K/min"}

#: (signal, kind, unit) of the clutch run's signals tested, in this order where a run has them; any other
#: channel of the runs is tested too. Temperatures are the measured ones, drop-outs held.
RUN_SIGNALS = (
    ("engine_speed", "input", "rpm"), ("clutch_speed", "input", "rpm"), ("slip_speed", "input", "rpm"),
    ("clutch_state", "input", "1"), ("clutch_torque", "input", "N*m"), ("load_torque", "input", "N*m"),
    ("friction_power", "input", "W"), ("T_ambient", "input", "degC"), ("T_flywheel", "measured", "degC"),
    ("T_air", "measured", "degC"), ("T_housing", "measured", "degC"), ("time", "input", "s"),
    ("time_since_slip", "derived", "s"),
)
DERIVED = {"slip_speed": ("engine_speed", "clutch_speed"), "time_since_slip": ("friction_power",)}  # from what


@dataclass(frozen=True)
class Evidence:
    """One test: how much of a channel's held-out residual variance the signal's binned means explain."""

    signal: str
    kind: str  # input, measured, derived (from the inputs) or model (a state of the fitted model)
    unit: str
    channel: str
    form: str  # level (the residual, K) or rate (its change over RATE_S, K/min)
    explained_pct: float  # η² of the residual in bins of the signal, %
    shifted_pct: float  # median η² over circular shifts: what autocorrelation alone explains, %
    p_value: float  # share of shifts explaining at least as much (with the unshifted one counted)
    samples: int

    def as_dict(self) -> dict:
        """The row as JSON-ready values."""
        return asdict(self)


def signal_unit(name: str, units: dict[str, str] | None = None) -> str:
    """The unit of a tested signal (model states in degC; other channels as their run file gives them)."""
    found = next((unit for n, _, unit in RUN_SIGNALS if n == name), None)
    return found or (units or {}).get(name) or ("degC" if name.startswith("model ") else "1")


def has_signal(name: str, channels: dict[str, np.ndarray]) -> bool:
    """Whether a run holds what the signal is computed from (load_torque is optional in a run file)."""
    return all(c in channels for c in DERIVED.get(name, (name,)))


def run_signal(name: str, channels: dict[str, np.ndarray], dt: float) -> np.ndarray:
    """A tested signal of one run at the fitting step: a channel (measured temperatures with drop-outs held),
    slip speed, or the time since the last slip."""
    if name == "time_since_slip":
        return time_since_slip(channels, dt)
    return signal_values(name, channels)


def tested_signals(datasets: Sequence[FitData], measured: Sequence[str]) -> list[tuple[str, str, str]]:
    """(signal, kind, unit) of every signal the runs hold: the clutch's list first, then any other channel that is
    not a temperature the model leaves unmeasured (a second sensor of a measured one, a part the model lacks)."""
    listed = [row for row in RUN_SIGNALS if all(has_signal(row[0], d.channels) for d in datasets)]
    names = {row[0] for row in RUN_SIGNALS}
    units = datasets[0].units
    shared = [c for c in datasets[0].channels if c not in names and all(c in d.channels for d in datasets)
              and (units.get(c) != "degC" or c in measured)]
    return listed + [(c, "measured" if c in measured else "input", units.get(c, "1")) for c in shared]


def residual_rate(residual: np.ndarray, dt: float, held_s: float = FOLD_S) -> np.ndarray:
    """Centred change of a residual over RATE_S in K/min; NaN where the window leaves the run or crosses
    from one held-out fold block (`held_s` long) to the next, whose prediction comes from another fit."""
    h = max(1, int(round(RATE_S / dt)))
    k = np.arange(len(residual))
    lo, hi = k - h // 2, k - h // 2 + h
    out = np.full(len(residual), np.nan)
    ok = (lo >= 0) & (hi < len(residual))
    ok[ok] &= (lo[ok] * dt // held_s) == (hi[ok] * dt // held_s)
    out[ok] = (residual[hi[ok]] - residual[lo[ok]]) / (h * dt / 60.0)
    return out


def residual_forms(held: HeldOut) -> dict[str, list[dict[str, np.ndarray]]]:
    """The tested forms of the held-out residuals: per form, per run, channel -> values (K or K/min)."""
    level = held.residuals()
    rate = [{c: residual_rate(r, d.dt) for c, r in run.items()} for run, d in zip(level, held.datasets)]
    return {"level": level, "rate": rate}


def model_states(spec: ModelSpec, params: dict[str, float], datasets: Sequence[FitData]) -> dict[str, list[np.ndarray]]:
    """Every state of the fitted model per run (degC), named `model T_<channel>` by the channel it is output as."""
    net = spec.network
    names = {state: channel for channel, state in net.outputs.items()}
    out: dict[str, list[np.ndarray]] = {f"model {names.get(s, s)}": [] for s in net.state_names}
    for d in datasets:
        states = run_network(net, params, d.channels, d.dt, initial_state(net, d, params), KEY_RESOLUTION)[:-1]
        for i, s in enumerate(net.state_names):
            out[f"model {names.get(s, s)}"].append(states[:, i])
    return out


def bin_labels(values: np.ndarray, bins: int = BINS) -> np.ndarray:
    """Bin index of each value: one bin per distinct value when there are few, else quantile bins,
    with a value held more than DOMINANT_SHARE of the time (0 rpm, 0 W) in a bin of its own."""
    distinct, counts = np.unique(values[np.isfinite(values)], return_counts=True)
    if len(distinct) <= bins:
        return np.searchsorted(distinct, values)
    dominant = counts.max() > DOMINANT_SHARE * counts.sum()
    held = values == distinct[np.argmax(counts)] if dominant else np.zeros(len(values), dtype=bool)
    inner = np.unique(np.nanquantile(values[~held], np.linspace(0, 1, bins + 1)[1:-1]))
    labels = np.searchsorted(inner, values, side="right")
    labels[held] = len(inner) + 1  # the dominant value alone in the bin after the last one
    return labels


def fast_length(n: int) -> int:
    """Samples of a run the test uses: the largest 11-smooth length up to n (scipy.fft.prev_fast_len; at most
    2.5 % shorter for runs of 10 minutes or more at 1 s), so the transforms stay fast for any run length
    (a prime length is ten times slower)."""
    return int(sp_fft.prev_fast_len(n, real=False))


def column_spectrum(columns: np.ndarray) -> np.ndarray:
    """Spectrum (3·column, frequency) of a run's count, value and square of its finite residuals (samples × column)."""
    valid = np.isfinite(columns)
    values = np.where(valid, columns, 0.0)
    return sp_fft.rfft(np.concatenate([valid, values, values * values], axis=1).T, axis=-1)


def _shifted_bin_sums(spectrum: np.ndarray, labels: np.ndarray, n_bins: int) -> np.ndarray:
    """For every circular shift k of the labels at once (FFT cross-correlation): per bin and column the count,
    sum and sum of squares of the finite residuals; shape (shift, 3, bin, column), row k = labels rolled by k."""
    n = len(labels)
    onehot = sp_fft.rfft((labels[None, :] == np.arange(n_bins)[:, None]).astype(float), axis=-1)
    sums = sp_fft.irfft(np.conj(onehot)[:, None, :] * spectrum[None], n=n, axis=-1)  # (bin, 3·column, shift)
    sums = sums.reshape(n_bins, 3, -1, n).transpose(3, 1, 0, 2)
    sums[:, 0] = np.rint(sums[:, 0])  # counts are whole numbers; the FFT leaves rounding noise
    return sums


def _eta_squared(sums: np.ndarray) -> np.ndarray:
    """Share of variance between the means of the bins holding MIN_BIN_SAMPLES samples or more, per column;
    `sums` (…, 3, bin, column) of count, sum and sum of squares."""
    count, total, squares = sums[..., 0, :, :], sums[..., 1, :, :], sums[..., 2, :, :]
    used = count >= MIN_BIN_SAMPLES
    n = np.sum(count * used, axis=-2)
    s = np.sum(total * used, axis=-2)
    with np.errstate(invalid="ignore", divide="ignore"):
        grand = np.where(n > 0, s * s / n, 0.0)
        between = np.sum(np.where(used, total * total / count, 0.0), axis=-2) - grand
        spread = np.sum(squares * used, axis=-2) - grand
        return np.where(spread > 0, between / spread, 0.0)


def shift_test(spectra: Sequence[np.ndarray], labels: Sequence[np.ndarray],
               offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column: η², median η² over circular shifts, p-value; `spectra` per run (column_spectrum), `labels`
    the signal's bins per run (as long as its fast_length), `offsets` the shifts (shifts × runs)."""
    n_bins = int(max(lab.max() for lab in labels)) + 1
    per_run = [_shifted_bin_sums(spectrum, lab, n_bins) for spectrum, lab in zip(spectra, labels)]
    observed = _eta_squared(sum(sums[0] for sums in per_run))
    null = _eta_squared(sum(sums[offsets[:, r]] for r, sums in enumerate(per_run)))
    return observed, np.median(null, axis=0), (1 + np.sum(null >= observed - 1e-12, axis=0)) / (1 + len(offsets))


def shift_offsets(lengths: Sequence[int], rng: np.random.Generator, shifts: int = SHIFTS) -> np.ndarray:
    """Random circular shifts (shifts × runs), each between MIN_SHIFT_FRACTION and 1 − that of its run's length."""
    fraction = rng.uniform(MIN_SHIFT_FRACTION, 1 - MIN_SHIFT_FRACTION, size=(shifts, len(lengths)))
    return (fraction * np.asarray(lengths)).astype(int)


def residual_evidence(held: HeldOut, spec: ModelSpec, params: dict[str, float], seed: int = 0) -> list[Evidence]:
    """Held-out residuals (level and rate) of each measured channel tested against every run signal and model state, ranked."""
    datasets = held.datasets
    forms = residual_forms(held)
    keys = [(form, c) for form, runs in forms.items() for c in runs[0]]
    lengths = [fast_length(len(d)) for d in datasets]
    columns = [np.column_stack([forms[form][i][c][:n] for form, c in keys]) for i, n in enumerate(lengths)]
    samples = np.sum([np.isfinite(col).sum(axis=0) for col in columns], axis=0)
    spectra = [column_spectrum(col) for col in columns]
    signals = [(name, kind, unit, [run_signal(name, d.channels, d.dt) for d in datasets])
               for name, kind, unit in tested_signals(datasets, spec.network.measured)]
    signals += [(name, "model", "degC", values) for name, values in model_states(spec, params, datasets).items()]
    offsets = shift_offsets(lengths, np.random.default_rng(seed))
    rows = []
    for name, kind, unit, values in signals:
        labels = np.split(bin_labels(np.concatenate(values)), np.cumsum([len(v) for v in values])[:-1])
        explained, shifted, p = shift_test(spectra, [lab[:n] for lab, n in zip(labels, lengths)], offsets)
        rows += [Evidence(name, kind, unit, c, form, 100 * float(explained[j]), 100 * float(shifted[j]),
                          float(p[j]), int(samples[j])) for j, (form, c) in enumerate(keys)]
    return sorted(rows, key=lambda e: (e.p_value, -(e.explained_pct - e.shifted_pct)))


@dataclass(frozen=True)
class BinnedMeans:
    """Mean residual per bin of a signal with its standard error, robust to autocorrelation within BLOCK_S blocks."""

    centre: np.ndarray  # median of the signal in the bin (signal's unit)
    mean: np.ndarray  # mean residual in the bin, K
    stderr: np.ndarray  # cluster-robust standard error of the mean, K (blocks of BLOCK_S as clusters)
    samples: np.ndarray


def binned_means(signal: Sequence[np.ndarray], residual: Sequence[np.ndarray], dt: float,
                 bins: int = BINS) -> BinnedMeans:
    """Binned mean residual against a signal (per-run arrays), with standard errors that count blocks, not samples.

    Var(mean) = Σ_blocks (Σ_block (e − mean))² / n²: samples within a 5-minute block are not independent.
    """
    block_len = max(1, int(BLOCK_S / dt))
    blocks = np.concatenate([i * 10 ** 9 + np.arange(len(s)) // block_len for i, s in enumerate(signal)])
    values, resid = np.concatenate(signal), np.concatenate(residual)
    labels = bin_labels(values, bins)
    use = np.isfinite(resid) & np.isfinite(values)
    centre, mean, stderr, samples = [], [], [], []
    for b in np.unique(labels[use]):
        sel = use & (labels == b)
        n = int(sel.sum())
        if n < MIN_BIN_SAMPLES:
            continue
        m = float(resid[sel].mean())
        _, cluster = np.unique(blocks[sel], return_inverse=True)
        sums = np.bincount(cluster, resid[sel] - m)
        centre.append(float(np.median(values[sel])))
        mean.append(m)
        stderr.append(float(np.sqrt(np.sum(sums ** 2)) / n))
        samples.append(n)
    order = np.argsort(centre)
    return BinnedMeans(*(np.asarray(a)[order] for a in (centre, mean, stderr, samples)))
