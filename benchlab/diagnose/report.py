"""diagnose(): the contract's JSON object (§3) from the engine's findings, with held-out regimes and residual evidence."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from benchlab.diagnose.engine import ALPHA, FOLD_S, MIN_GAIN_PCT, STEP_S, Diagnosis, Finding, diagnose_runs
from benchlab.diagnose.evidence import BINS, RATE_S, SHIFTS, residual_evidence
from benchlab.diagnose.regimes import COOLDOWN_SPLIT_S, regime_errors
from benchlab.metrics import RESIDUAL_LABEL
from benchlab.model.definition import ModelDefinition


def _finding_json(f: Finding) -> dict:
    c = f.candidate
    return {"signal": c.signal, "mechanism": c.mechanism, "summary": c.summary, "extension": c.extension,
            "rmse_before_K": f.before.rmse, "rmse_after_K": f.after.rmse, "gain_pct": f.gain_pct,
            "p_value": f.p_value, "bic_delta": f.bic_delta, "candidate": c.key,
            "params": {name: f.params[name] for name in f.added}}


def summarise(result: Diagnosis, baseline: str) -> dict:
    """Contract JSON of a diagnosis: baseline held-out error, findings by gain, best model, regimes, evidence."""
    final = result.final
    return {
        "baseline": {"model": baseline, "rmse_K": result.baseline_held.rmse,
                     "nrmse_pct": result.baseline_held.nrmse_pct},
        "findings": [_finding_json(f) for f in result.findings],
        "best": {"model": final.spec.name, "rmse_K": result.final_held.rmse,
                 "nrmse_pct": result.final_held.nrmse_pct, "params": final.params},
        "regimes": {"baseline": regime_errors(result.baseline_held), "best": regime_errors(result.final_held)},
        "evidence": [e.as_dict() for e in residual_evidence(result.baseline_held, result.baseline.spec,
                                                             result.baseline.params)],
        "method": {"validation": f"blocked 2-fold: {FOLD_S:.0f} s blocks dealt alternately to the folds; "
                                 "fit on one fold of each run, score on the other",
                   "step_s": STEP_S, "min_gain_pct": MIN_GAIN_PCT, "alpha": ALPHA,
                   "gain": "held-out RMSE without the extension vs with it; with several findings, "
                           "the combined model without it (drop-one) vs the combined model",
                   "bic_delta": "second to the held-out test and reported, not decided on: in-sample BIC with the "
                                "extension minus without it, n taken as the residuals' effective sample size "
                                "n (1 - rho) / (1 + rho); negative favours the extension",
                   "regimes": f"RMSE of the held-out residuals ({RESIDUAL_LABEL}, each sample predicted by the "
                              "fold fit that did not see it) per regime and measured channel; cooldown: samples not "
                              "slipping by the time since the last slipping sample (or the run's start), "
                              f"< {COOLDOWN_SPLIT_S:g} s or >= {COOLDOWN_SPLIT_S:g} s",
                   "evidence": f"baseline held-out residuals (level in K, and rate: change over {RATE_S:g} s in "
                               f"K/min) against each signal: share of their variance explained by the means in "
                               f"{BINS} bins of the signal; p-value from {SHIFTS} circular shifts of the signal "
                               "against the residual (autocorrelation kept); ranked by p-value, then by the share "
                               "beyond the shifted median"},
    }


def diagnose(runs: Sequence[pd.DataFrame], baseline: "str | ModelDefinition" = "linear", seed: int = 0) -> dict:
    """Contract JSON: baseline held-out error, findings ordered by gain, best combined model, regimes, evidence."""
    result = diagnose_runs(runs, baseline, seed=seed)
    return summarise(result, result.baseline.spec.name)
