"""Where the model is wrong: its held-out error broken down by operating regime, per measured channel.

The residuals are the held-out ones of the engine (each sample predicted by the fold fit that did not
see it), never an in-sample fit's: a regime where the model is wrong must not look right because the
fit bent its parameters towards it. Regimes, each sample labelled once per group:

- `phase`: slipping (friction power > 0), locked (clamped, not slipping), open (clutch state 0);
- `engine_speed_rpm`: engine-speed bands;
- `clutch_state`: clamped or open;
- `cooldown`: samples not slipping, short (< COOLDOWN_SPLIT_S since the last slipping sample, or since the
  run's start where none was before) or long (at least COOLDOWN_SPLIT_S): the paper's conclusion that the
  nonlinear model matters for cool-downs of more than 120 s;
- `T_flywheel_degC`: the measured flywheel temperature's level (drop-outs held at the last reading);
- `all`: every sample (the channel's whole held-out RMSE).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from benchlab.diagnose.engine import HeldOut
from benchlab.identify.data import FitData

COOLDOWN_SPLIT_S = 120.0
SPEED_BANDS_RPM = (1250.0, 1750.0)
TEMPERATURE_BANDS_C = (40.0, 60.0)
MIN_REGIME_SAMPLES = 60  # a regime shorter than a minute at 1 s is not named the worst


def time_since_slip(channels: dict[str, np.ndarray], dt: float) -> np.ndarray:
    """Seconds since the last slipping sample (friction power > 0), or since the run's start before the first; 0 while slipping."""
    n = len(channels["friction_power"])
    index = np.arange(n)
    last = np.maximum.accumulate(np.where(channels["friction_power"] > 0, index, 0))
    return (index - last) * dt


def _band_names(edges: Sequence[float]) -> list[str]:
    """Names of the bands the edges cut: `<e0`, `e0-e1`, …, `>=eN` (edges in the values' unit)."""
    return [f"<{edges[0]:g}"] + [f"{lo:g}-{hi:g}" for lo, hi in zip(edges[:-1], edges[1:])] + [f">={edges[-1]:g}"]


def _bands(values: np.ndarray, edges: Sequence[float]) -> np.ndarray:
    """Band name of each value."""
    return np.array(_band_names(edges), dtype=object)[np.searchsorted(edges, values, side="right")]


SHORT, LONG = f"<{COOLDOWN_SPLIT_S:g} s", f">={COOLDOWN_SPLIT_S:g} s"
#: Each group's regimes in the order they are shown.
REGIMES = {"all": ["all"], "phase": ["slipping", "locked", "open"], "engine_speed_rpm": _band_names(SPEED_BANDS_RPM),
           "clutch_state": ["clamped", "open"], "cooldown": [SHORT, LONG],
           "T_flywheel_degC": _band_names(TEMPERATURE_BANDS_C)}


#: The channels each regime group is labelled from: a group is left out where the runs lack one (a model that is
#: not the clutch gets "all" alone).
REGIME_CHANNELS = {"all": (), "phase": ("clutch_state", "friction_power"), "engine_speed_rpm": ("engine_speed",),
                   "clutch_state": ("clutch_state",), "cooldown": ("friction_power",),
                   "T_flywheel_degC": ("T_flywheel",)}


def regime_labels(d: FitData) -> dict[str, np.ndarray]:
    """Each regime group's label per sample of one run at the fitting step (None: not in the group, e.g. a
    slipping sample is in no cool-down); only the groups whose channels the run holds."""
    ch = d.channels
    groups = [g for g, needs in REGIME_CHANNELS.items() if all(c in ch for c in needs)]
    out = {}
    for group in groups:
        if group == "all":
            out[group] = np.full(len(d), "all", dtype=object)
        elif group == "phase":
            slipping, clamped = ch["friction_power"] > 0, ch["clutch_state"] >= 0.5
            out[group] = np.where(slipping, "slipping", np.where(clamped, "locked", "open")).astype(object)
        elif group == "engine_speed_rpm":
            out[group] = _bands(ch["engine_speed"], SPEED_BANDS_RPM)
        elif group == "clutch_state":
            out[group] = np.where(ch["clutch_state"] >= 0.5, "clamped", "open").astype(object)
        elif group == "cooldown":
            since = time_since_slip(ch, d.dt)
            out[group] = np.where(ch["friction_power"] > 0, None,
                                  np.where(since < COOLDOWN_SPLIT_S, SHORT, LONG)).astype(object)
        else:
            out[group] = _bands(ch["T_flywheel"], TEMPERATURE_BANDS_C)
    return out


def _rmse(errors: np.ndarray) -> dict:
    return {"rmse_K": float(np.sqrt(np.mean(errors ** 2))) if errors.size else None, "samples": int(errors.size)}


def regime_errors(held: HeldOut) -> dict[str, dict]:
    """Held-out RMSE (K) and sample count per regime group, label and measured channel, plus over all channels.

    Shape: {group: {label: {"rmse_K", "samples", "channels": {channel: {"rmse_K", "samples"}}}}}; every regime
    of REGIMES whose channels the runs hold is listed, with "rmse_K": null where they hold no sample of it.
    """
    residuals = held.residuals()
    labels = [regime_labels(d) for d in held.datasets]
    errors = {c: np.concatenate([r[c] for r in residuals]) for c in residuals[0]}
    out: dict[str, dict] = {}
    for group in (g for g in REGIMES if all(g in run for run in labels)):
        lab = np.concatenate([run[group] for run in labels])
        out[group] = {}
        for value in REGIMES[group]:
            per_channel = {c: err[(lab == value) & np.isfinite(err)] for c, err in errors.items()}
            row = _rmse(np.concatenate(list(per_channel.values())))
            out[group][value] = {**row, "channels": {c: _rmse(e) for c, e in per_channel.items()}}
    return out


def worst_regimes(regimes: dict[str, dict], count: int = 5) -> list[tuple[str, str, str, float, int]]:
    """(group, label, channel, RMSE K, samples) of the largest per-channel errors over at least MIN_REGIME_SAMPLES samples."""
    rows = [(group, label, c, e["rmse_K"], e["samples"])
            for group, labels in regimes.items() if group != "all" for label, entry in labels.items()
            for c, e in entry["channels"].items() if e["samples"] >= MIN_REGIME_SAMPLES]
    return sorted(rows, key=lambda row: -row[3])[:count]
