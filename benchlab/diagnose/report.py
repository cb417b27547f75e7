"""diagnose(): the contract's JSON object (§3) from the engine's findings."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from benchlab.diagnose.engine import ALPHA, MIN_GAIN_PCT, STEP_S, Finding, HeldOut, diagnose_runs
from benchlab.diagnose.regimes import regime_errors
from benchlab.clutch import NONLINEAR_PARAMS as CLUTCH_PARAMS
from benchlab.identify.data import prepare


def _nrmse_pct(held: HeldOut, runs: Sequence[pd.DataFrame]) -> float:
    span = np.mean([np.nanmax(r[c]) - np.nanmin(r[c]) for r in runs for c in ("T_flywheel", "T_air", "T_housing")])
    return float(100 * held.rmse / span)


def _finding_json(f: Finding) -> dict:
    c = f.candidate
    return {"signal": c.signal, "mechanism": c.mechanism, "summary": c.summary, "extension": c.extension,
            "rmse_before_K": f.before.rmse, "rmse_after_K": f.after.rmse, "gain_pct": f.gain_pct,
            "p_value": f.p_value, "candidate": c.key,
            "params": {p.name: f.params[p.name] for p in f.spec.free if p.name not in CLUTCH_PARAMS}}


def diagnose(runs: Sequence[pd.DataFrame], baseline: str = "linear", seed: int = 0) -> dict:
    """Contract JSON: baseline held-out error, findings ordered by gain, best combined model, regimes."""
    base, base_held, findings, final = diagnose_runs(runs, baseline, seed=seed)
    best_held = findings[-1].after if findings else base_held
    datasets = [prepare(r, STEP_S) for r in runs]
    return {
        "baseline": {"model": baseline, "rmse_K": base_held.rmse, "nrmse_pct": _nrmse_pct(base_held, runs)},
        "findings": sorted((_finding_json(f) for f in findings), key=lambda j: -j["gain_pct"]),
        "best": {"model": final.spec.name, "rmse_K": best_held.rmse, "nrmse_pct": _nrmse_pct(best_held, runs),
                 "params": final.params},
        "regimes": {"baseline": regime_errors(base.spec, base.params, datasets),
                    "best": regime_errors(final.spec, final.params, datasets)},
        "method": {"validation": "blocked 2-fold: fit on one half of each run, score on the other",
                   "step_s": STEP_S, "min_gain_pct": MIN_GAIN_PCT, "alpha": ALPHA},
    }
