"""Where the model is wrong: held-out error broken down by operating regime."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from benchlab.identify.data import FitData
from benchlab.identify.fit import simulate_outputs
from benchlab.identify.spec import ModelSpec

SPEED_BANDS_RPM = ((0, 1250), (1250, 1750), (1750, 10000))
TEMPERATURE_BANDS_C = ((-50, 40), (40, 60), (60, 400))


def regime_errors(spec: ModelSpec, params: dict[str, float], datasets: Sequence[FitData]) -> dict[str, dict]:
    """RMSE (K) of the flywheel temperature per regime: slip state, engine-speed band, temperature level."""
    errors, labels = [], {"phase": [], "engine_speed_rpm": [], "clutch_state": [], "T_flywheel_degC": []}
    for d in datasets:
        sim = simulate_outputs(spec.network, params, d)
        target = d.targets.get("T_flywheel")
        if target is None:
            continue
        err = sim["T_flywheel"] - target
        ch = d.channels
        phase = np.where(ch["friction_power"] > 0, "slipping", np.where(ch["clutch_state"] >= 0.5, "locked", "open"))
        errors.append(err)
        labels["phase"].append(phase)
        labels["clutch_state"].append(np.where(ch["clutch_state"] >= 0.5, "clamped", "open"))
        labels["engine_speed_rpm"].append(_band(ch["engine_speed"], SPEED_BANDS_RPM))
        labels["T_flywheel_degC"].append(_band(target, TEMPERATURE_BANDS_C))
    err = np.concatenate(errors)
    out: dict[str, dict] = {}
    for key, parts in labels.items():
        lab = np.concatenate(parts)
        out[key] = {}
        for value in sorted(set(lab)):
            sel = (lab == value) & np.isfinite(err)
            if sel.sum():
                out[key][value] = {"rmse_K": float(np.sqrt(np.mean(err[sel] ** 2))), "samples": int(sel.sum())}
    return out


def _band(values: np.ndarray, bands) -> np.ndarray:
    out = np.full(len(values), "n/a", dtype=object)
    for lo, hi in bands:
        out[(values >= lo) & (values < hi)] = f"{lo}-{hi}"
    return out
