"""diagnose(): the contract's JSON object (§3) from the engine's findings, with held-out regimes and residual evidence."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from benchlab.diagnose.engine import (ALPHA, CROSS_VALIDATED, FOLD_S, MIN_GAIN_PCT, SCORED_FITS, STEP_S,
                                     STRUCTURAL_FITS, Diagnosis,
                                     Finding, diagnose_runs)
from benchlab.diagnose.evidence import BINS, RATE_S, SHIFTS, residual_evidence
from benchlab.diagnose.library import telling_apart
from benchlab.diagnose.regimes import COOLDOWN_SPLIT_S, regime_errors
from benchlab.metrics import RESIDUAL_LABEL
from benchlab.model.definition import ModelDefinition


def _unit(f: Finding, name: str) -> str:
    """A parameter's unit as the extended model file gives it (the library writes one for each it adds)."""
    found = f.spec.definition.parameters.get(name)
    return found.unit if found is not None else ""


def _finding_json(f: Finding, model: ModelDefinition) -> dict:
    """Contract §3 keys, then the test figures, the fitted extension, and the alternatives the data cannot rule out
    with the measurement that would."""
    c = f.candidate
    out = {"signal": c.signal, "mechanism": c.mechanism, "summary": c.summary, "extension": c.extension,
           "signals": list(c.reads),
           "rmse_before_K": f.before.rmse, "rmse_after_K": f.after.rmse, "gain_pct": f.gain_pct,
           "p_value": f.p_value, "bic_delta": f.bic_delta, "candidate": c.key,
           "params": {name: f.params[name] for name in f.added},
           "units": {name: _unit(f, name) for name in f.added}, "at_bound": list(f.at_bound),
           "ambiguous": bool(f.alternatives),
           "alternatives": [{"candidate": a.candidate.key, "signal": a.candidate.signal,
                             "mechanism": a.candidate.mechanism, "extension": a.candidate.extension,
                             "gain_pct": a.gain_pct, "n_params": a.added, "p_value": a.p_value,
                             "p_vs_finding": a.p_vs_winner,
                             "tell_apart_by": telling_apart(model, c, a.candidate)} for a in f.alternatives]}
    return out


def summarise(result: Diagnosis, baseline: str) -> dict:
    """Contract JSON of a diagnosis: baseline held-out error, findings by gain, best model, regimes, evidence."""
    final = result.final
    return {
        "baseline": {"model": baseline, "rmse_K": result.baseline_held.rmse,
                     "nrmse_pct": result.baseline_held.nrmse_pct},
        "findings": [_finding_json(f, result.baseline.spec.definition) for f in result.findings],
        "best": {"model": final.spec.name, "rmse_K": result.final_held.rmse,
                 "nrmse_pct": result.final_held.nrmse_pct, "params": final.params},
        "regimes": {"baseline": regime_errors(result.baseline_held), "best": regime_errors(result.final_held)},
        "evidence": [e.as_dict() for e in residual_evidence(result.baseline_held, result.baseline.spec,
                                                             result.baseline.params)],
        "method": {"validation": f"blocked 2-fold: {FOLD_S:.0f} s blocks dealt alternately to the folds; "
                                 "fit on one fold of each run, score on the other",
                   "step_s": STEP_S, "min_gain_pct": MIN_GAIN_PCT, "alpha": ALPHA,
                   "search": f"candidates generated from the model's structure, each starting nested (no effect); "
                             f"a score test (one Gauss-Newton step, every parameter free; extra nodes, new links and "
                             f"lags from screening starts) ranks them, the {SCORED_FITS} best and the "
                             f"{STRUCTURAL_FITS} best extra nodes and lags get a short fit, the "
                             f"{CROSS_VALIDATED} best of those are fitted from the warm and the neutral start and "
                             "cross-validated; after each acceptance the whole model is refitted with multistart",
                   "failed_fits": [{"candidate": key, "at_bound": list(names)} for key, names in result.failed_fits],
                   "baseline_at_bound": list(result.baseline_at_bound),
                   "named": "of the extensions that pass, the simplest other explanation (fewest added parameters, "
                            "then signals) that the largest gain does not beat at alpha, else the largest gain; "
                            "every screened candidate no more complex than the one named is cross-validated first",
                   "alternatives": "other extensions that passed against the same parent and that the finding does "
                                   "not beat at alpha (the same block test between the two), with the measurement "
                                   "that would tell them apart",
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
