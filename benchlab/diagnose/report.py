"""diagnose(): the contract's JSON object (§3) from the engine's findings."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from benchlab.diagnose.engine import ALPHA, FOLD_S, MIN_GAIN_PCT, STEP_S, Finding, HeldOut, diagnose_runs
from benchlab.diagnose.regimes import regime_errors
from benchlab.identify.data import prepare


def _nrmse_pct(held: HeldOut, runs: Sequence[pd.DataFrame]) -> float:
    span = np.mean([np.nanmax(r[c]) - np.nanmin(r[c]) for r in runs for c in ("T_flywheel", "T_air", "T_housing")])
    return float(100 * held.rmse / span)


def _finding_json(f: Finding) -> dict:
    c = f.candidate
    return {"signal": c.signal, "mechanism": c.mechanism, "summary": c.summary, "extension": c.extension,
            "rmse_before_K": f.before.rmse, "rmse_after_K": f.after.rmse, "gain_pct": f.gain_pct,
            "p_value": f.p_value, "candidate": c.key,
            "params": {name: f.params[name] for name in f.added}}


def diagnose(runs: Sequence[pd.DataFrame], baseline: str = "linear", seed: int = 0) -> dict:
    """Contract JSON: baseline held-out error, findings ordered by gain, best combined model, regimes."""
    result = diagnose_runs(runs, baseline, seed=seed)
    datasets = [prepare(r, STEP_S) for r in runs]
    final = result.final
    return {
        "baseline": {"model": baseline, "rmse_K": result.baseline_held.rmse,
                     "nrmse_pct": _nrmse_pct(result.baseline_held, runs)},
        "findings": [_finding_json(f) for f in result.findings],
        "best": {"model": final.spec.name, "rmse_K": result.final_held.rmse,
                 "nrmse_pct": _nrmse_pct(result.final_held, runs), "params": final.params},
        "regimes": {"baseline": regime_errors(result.baseline.spec, result.baseline.params, datasets),
                    "best": regime_errors(final.spec, final.params, datasets)},
        "method": {"validation": f"blocked 2-fold: {FOLD_S:.0f} s blocks dealt alternately to the folds; "
                                 "fit on one fold of each run, score on the other",
                   "step_s": STEP_S, "min_gain_pct": MIN_GAIN_PCT, "alpha": ALPHA,
                   "gain": "held-out RMSE without the extension vs with it; with several findings, "
                           "the combined model without it (drop-one) vs the combined model"},
    }
