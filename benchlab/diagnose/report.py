"""diagnose(): the contract's JSON object (§3) from the engine's findings, with held-out regimes and residual evidence."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict

import numpy as np
import pandas as pd

from benchlab.diagnose.engine import (ALPHA, BEYOND_FLOOR, COMPOSED_FITS, CROSS_VALIDATED, FOLD_S, MIN_GAIN_PCT,
                                     SCORED_FITS, STEP_S, STRUCTURAL_FITS, SWITCH_FITS, Diagnosis, Finding, HeldOut,
                                     block_test, diagnose_runs, gain_pct, run_groups)
from benchlab.diagnose.evidence import BINS, RATE_S, SHIFTS
from benchlab.diagnose.library import telling_apart
from benchlab.diagnose.regimes import COOLDOWN_SPLIT_S, regime_errors
from benchlab.identify.data import SLIP_POWER
from benchlab.identify.metrics import RESIDUAL_LABEL
from benchlab.identify.uncertainty import estimate_uncertainty
from benchlab.model.definition import ModelDefinition
from benchlab.model.expressions import compile_expression


def _unit(f: Finding, name: str) -> str:
    """A parameter's unit as the extended model file gives it (the library writes one for each it adds)."""
    found = f.spec.definition.parameters.get(name.split("@")[0])
    return found.unit if found is not None else ""


def final_standard_errors(result: Diagnosis) -> dict[str, float]:
    """The final model's standard errors: its fit's sandwich covariance of the residuals (benchlab.identify.uncertainty)."""
    datasets = result.final_held.datasets
    return estimate_uncertainty(result.final, datasets, [{} for _ in datasets]).standard_errors


def per_group_values(f: Finding, result: Diagnosis, errors: dict[str, float]) -> list[dict]:
    """For a finding that splits a parameter per run group: each group's runs (their order on the command line), its
    value in the final model and the value's standard error (`errors`, final_standard_errors), so a lab sees how far
    apart the runs are against how well each is known. A lead's split is out of the final model: its own refit's
    value, with no standard error."""
    datasets = result.final_held.datasets
    out = []
    for name in f.candidate.splits:
        for group in run_groups(datasets):
            key = f"{name}@{group}"
            out.append({"parameter": name, "group": group, "value": result.final.params.get(key, f.params.get(key)),
                        "standard_error": errors.get(key, float("nan")), "unit": _unit(f, name),
                        "runs": [i for i, d in enumerate(datasets) if d.group_label == group]})
    return out


#: a split per run group is named only where two groups' values differ by more than this many of their combined
#: standard errors, |a - b| > SPLIT_SEPARATION * sqrt(se_a^2 + se_b^2); closer groups are one value told twice
SPLIT_SEPARATION = 2.0


def split_reasons(groups: Sequence[dict]) -> list[str]:
    """Why a per-group split (per_group_values) is not a cause: a split parameter no two of whose groups differ by
    more than SPLIT_SEPARATION combined standard errors (a NaN standard error separates nothing)."""
    reasons = []
    for name in dict.fromkeys(g["parameter"] for g in groups):
        own = [g for g in groups if g["parameter"] == name]
        apart = [abs(a["value"] - b["value"]) / math.hypot(a["standard_error"], b["standard_error"])
                 for i, a in enumerate(own) for b in own[i + 1:]]
        widest = max((x for x in apart if math.isfinite(x)), default=float("nan"))
        if not widest > SPLIT_SEPARATION:
            reasons.append(f"the groups' {name} differ by at most {widest:.2g} combined standard errors "
                           f"(the runs disagree only beyond {SPLIT_SEPARATION:g})")
    return reasons


#: the measured heat input and its factors (P = clutch torque x slip speed): the model already puts all of it in, so a
#: further source that reads them and adds net heat over the runs creates energy
MEASURED_POWER = (SLIP_POWER, "slip_speed", "clutch_torque")


def energy_reasons(f: Finding, result: Diagnosis) -> list[str]:
    """Why a finding creates energy: a source it adds itself (not in the model it was measured against, its parent:
    another finding's source is that finding's) that reads the measured friction power or its factors
    (MEASURED_POWER), no temperature, and whose heat integrated over the diagnosed runs is a net input (J), on top of
    the friction heat the model already holds."""
    parent = (f.parent[0] if f.parent is not None else result.baseline.spec).definition
    model, before = f.spec.definition, {s.name for s in parent.sources}
    values = {**f.params, **result.final.params}
    reasons = []
    for source in model.sources:
        reads = source.heat.names
        if (source.name in before or reads & set(model.nodes) or not reads & set(MEASURED_POWER)
                or not reads & set(model.parameters) <= set(values)):  # a source split per run group: left out
            continue
        kinds = {name: "parameter" if name in model.parameters else "channel" for name in reads}
        heat = compile_expression(source.heat, kinds)
        joules = sum(float(np.sum(np.broadcast_to(heat(values, d.channels, {}), (len(d),)))) * d.dt
                     for d in result.final_held.datasets)
        if joules > 0:
            reasons.append(f"{source.name} adds {joules / 1e3:.3g} kJ over the runs on top of the measured friction "
                           "power it reads: it creates energy")
    return reasons


def label_json(f: Finding, floor: dict, groups: Sequence[dict], energy: Sequence[str] = ()) -> dict:
    """A finding's label and why: a patch (a description of the misfit, not a mechanism) where the final model stays
    BEYOND_FLOOR x the noise floor, its added parameters are not identified, its split per run group does not
    separate the groups (split_reasons) or it creates energy (`energy`, energy_reasons); else a lead where its gain
    does not carry to the unseen runs; else a cause."""
    patch = [f"{name} not identified: {why}" for name, why in f.not_identified.items()]
    patch += split_reasons(groups) + list(energy)
    if floor["beyond_library"]:
        patch.append(f"the final model stays {floor['best_ratio']:.1f}x the noise floor (>= {BEYOND_FLOOR:g}x): "
                     "no candidate explains the remainder, so this extension describes the misfit, not its cause")
    lead = [r for r in f.lead_reasons if r not in patch]
    return {"label": "patch" if patch else "lead" if lead else "cause", "label_reasons": patch or lead}


def unseen_json(before: HeldOut | None, after: HeldOut | None) -> dict | None:
    """A model and the one it improves on, both fitted on the diagnosed runs, scored on the unseen runs: RMSE
    before/after over all of them (with the block test's p-value) and per unseen run (in --validate order)."""
    if before is None or after is None:
        return None
    runs = [{"run": i, "rmse_before_K": HeldOut([d], [b], []).rmse, "rmse_after_K": HeldOut([d], [a], []).rmse}
            for i, (d, b, a) in enumerate(zip(before.datasets, before.predictions, after.predictions))]
    return {"rmse_before_K": before.rmse, "rmse_after_K": after.rmse, "gain_pct": gain_pct(before, after),
            "p_value": block_test(before, after), "runs": runs}


def sensors_json(f: Finding, result: Diagnosis) -> list[list[dict]]:
    """Per alternative of `f`, every place a sensor could go, ranked on the diagnosed runs as `benchlab design`
    ranks it (`design/sensors.py` `rank_diagnosed_sensors`, from the fits the diagnosis kept): the plate variance it
    removes under the finding's model, what it adds to the test between the finding and the alternative."""
    if not f.alternatives:
        return []
    from benchlab.design.sensors import rank_diagnosed_sensors

    ranked = rank_diagnosed_sensors(f.alternatives[0].named, [(a.spec, a.params) for a in f.alternatives],
                                    result.final_held.datasets)
    return [[asdict(s) for s in worths] for worths in ranked]


def _finding_json(f: Finding, model: ModelDefinition, result: Diagnosis, errors: dict[str, float],
                  floor: dict) -> dict:
    """Contract §3 keys, the gain on unseen runs, then the test figures, the fitted extension, and the alternatives
    the data cannot rule out with the measurement that would and each sensor place's worth (sensors_json); for runs
    that disagree, each group's value; for a lead, why it is not a cause; its label (label_json)."""
    c = f.candidate
    sensors = sensors_json(f, result)
    out = {"signal": c.signal, "mechanism": c.mechanism, "summary": c.summary, "extension": c.extension,
           "signals": list(c.reads), "unseen_gain_pct": f.unseen_gain_pct,
           "unseen": unseen_json(f.unseen_before, f.unseen_after),
           "rmse_before_K": f.before.rmse, "rmse_after_K": f.after.rmse, "gain_pct": f.gain_pct,
           "p_value": f.p_value, "bic_delta": f.bic_delta, "candidate": c.key,
           "params": {name: f.params[name] for name in f.added},
           "units": {name: _unit(f, name) for name in f.added}, "at_bound": list(f.at_bound),
           "run_gain_pct": f.run_gain_pct, "round": f.round, "not_identified": dict(f.not_identified),
           "ambiguous": bool(f.alternatives),
           "alternatives": [{"candidate": a.candidate.key, "signal": a.candidate.signal,
                             "mechanism": a.candidate.mechanism, "extension": a.candidate.extension,
                             "gain_pct": a.gain_pct, "n_params": a.added, "p_value": a.p_value,
                             "p_vs_finding": a.p_vs_winner,
                             "tell_apart_by": telling_apart(model, c, a.candidate), "sensors": places}
                            for a, places in zip(f.alternatives, sensors)]}
    groups = per_group_values(f, result, errors) if c.splits else []
    if groups:
        out["per_group"] = groups
    out.update(label_json(f, floor, groups, energy_reasons(f, result)))
    if f.lead_reasons:
        out["reasons"] = f.lead_reasons
    return out


def bounds_json(result: Diagnosis) -> list[dict]:
    """The baseline's parameters on a bound: which bound, the value, and what to widen in the model file."""
    specs = {p.name: p for p in result.baseline.spec.free}
    out = []
    for name, side in result.baseline_at_bound:
        limit = specs[name].lower if side == "min" else specs[name].upper
        out.append({"parameter": name, "bound": side, "value": result.baseline.params[name], "limit": limit,
                    "advice": f"held at its {side} while candidates were judged; where values "
                              f"{'below' if side == 'min' else 'above'} {limit:.6g} are physical, widen "
                              f"{name}'s {side} in the model file and diagnose again"})
    return out


def floor_json(result: Diagnosis) -> dict:
    """The measurements' noise floor, how far above it the baseline and the final model stay, and, where the final
    model stays far above it, that the rest of the error is beyond what the library can name."""
    floor = result.noise_floor
    baseline, best = result.baseline_held.rmse / floor, result.final_held.rmse / floor
    if not math.isfinite(best):
        verdict = "no noise floor: no target has ten valid samples in a row"
    elif best < BEYOND_FLOOR:
        verdict = f"the final model is within {BEYOND_FLOOR:g}x the noise floor: nothing large is left unexplained"
    else:
        verdict = (f"the remaining error is {best:.1f}x the noise floor and no candidate of the library explains it: "
                   "its cause is beyond what diagnose can name (see the evidence and the regimes for where it sits)")
    return {"noise_K": floor, "baseline_ratio": baseline, "best_ratio": best,
            "beyond_library": bool(math.isfinite(best) and best >= BEYOND_FLOOR),
            "verdict": verdict}


def summarise(result: Diagnosis, baseline: str) -> dict:
    """Contract JSON of a diagnosis: baseline held-out error, findings by gain, best model, regimes, evidence."""
    final = result.final
    errors = final_standard_errors(result) if any(f.candidate.splits for f in result.findings) else {}
    unseen = unseen_json(result.unseen_baseline, result.unseen_final)
    floor = floor_json(result)
    return {
        "baseline": {"model": baseline, "rmse_K": result.baseline_held.rmse,
                     "nrmse_pct": result.baseline_held.nrmse_pct},
        "findings": [_finding_json(f, result.baseline.spec.definition, result, errors, floor)
                     for f in result.findings],
        "leads": [_finding_json(f, result.baseline.spec.definition, result, errors, floor) for f in result.leads],
        "best": {"model": final.spec.name, "unseen_gain_pct": unseen["gain_pct"] if unseen else None,
                 "unseen": unseen, "rmse_K": result.final_held.rmse,
                 "nrmse_pct": result.final_held.nrmse_pct, "params": final.params},
        "floor": floor,
        "regimes": {"baseline": regime_errors(result.baseline_held), "best": regime_errors(result.final_held)},
        "evidence": [e.as_dict() for e in result.evidence],
        "method": {"validation": f"blocked 2-fold: {FOLD_S:.0f} s blocks dealt alternately to the folds; "
                                 "fit on one fold of each run, score on the other",
                   "step_s": STEP_S, "min_gain_pct": MIN_GAIN_PCT, "alpha": ALPHA,
                   "search": f"candidates generated from the model's structure, each starting nested (no effect); "
                             f"a score test (one Gauss-Newton step, every parameter free; extra nodes, new links and "
                             f"lags from screening starts) ranks them, the {SCORED_FITS} best and the "
                             f"{STRUCTURAL_FITS} best extra nodes and lags, the {SWITCH_FITS} best switch with hysteresis on a "
                             f"temperature's level (with its latch) and the {COMPOSED_FITS} best two-step "
                             "compositions (a new link with its per-run split or a signal law) get a short fit, the "
                             f"{CROSS_VALIDATED} best of those are fitted from the warm and the neutral start and "
                             "cross-validated; after each acceptance the whole model is refitted with multistart",
                   "failed_fits": [{"candidate": key, "at_bound": list(names)} for key, names in result.failed_fits],
                   "not_carried": [{"candidate": key, "run_gain_pct": gain} for key, gain in result.not_carried],
                   "held_out_runs": "with several runs, the named extension must also lower the leave-one-run-out "
                                    f"RMSE by {MIN_GAIN_PCT:g} % (each run predicted by a fit on the others, from its "
                                    "first readings); run_gain_pct is that gain, not_carried the named ones that did "
                                    "not; a parameter split per run group (mechanism per_run) is exempt, as it says "
                                    "the runs differ: its test is on held-out blocks of each run",
                   "baseline_at_bound": [name for name, _ in result.baseline_at_bound],
                   "baseline_bounds": bounds_json(result),
                   "named": "of the extensions that pass, the simplest other explanation (fewest added parameters, "
                            "then signals) that the largest gain does not beat at alpha, else the largest gain; "
                            "every screened candidate no more complex than the one named is cross-validated first",
                   "alternatives": "other extensions that passed against the same parent and that the finding does "
                                   "not beat at alpha (the same block test between the two), with the measurement "
                                   "that would tell them apart",
                   "gain": "held-out RMSE without the extension vs with it; with several findings, "
                           "the combined model without it (drop-one) vs the combined model",
                   "unseen": "with --validate runs: the same two models fitted on all of the diagnosed runs, "
                             "simulated on the unseen runs from their first readings (unseen_gain_pct, p_value: the "
                             "block test on their blocks); the best model against the baseline likewise",
                   "causes": "a finding is a cause when the final fit identifies its added parameters (none on a "
                             "bound, none with a sandwich standard error above its value: "
                             "benchlab.identify.identifiability) and, with --validate runs, its unseen gain passes "
                             f"the in-run rule (>= {MIN_GAIN_PCT:g} %, p < {ALPHA:g}); otherwise it is a lead "
                             "(reasons), taken out of the model, the rest refitted and re-checked",
                   "label": "each finding and lead is labelled: patch (a description of the misfit, not a "
                            f"mechanism) where the final model stays >= {BEYOND_FLOOR:g}x the noise floor, an added "
                            "parameter is not identified, a source it adds reads the measured friction power or its "
                            "factors and adds net heat over the runs (energy created), or a split per run group has "
                            "no two groups whose values "
                            f"differ by more than {SPLIT_SEPARATION:g} * sqrt(se_a^2 + se_b^2); else lead where its "
                            "gain does not carry to the unseen runs; else cause; label_reasons says why",
                   "floor": "noise_K: the fitting targets' white noise from their second differences "
                            "(median absolute deviation / sqrt(6), pooled), what a perfect model scores; ratios are "
                            f"held-out RMSE / noise_K; beyond_library where the final model stays >= {BEYOND_FLOOR:g}x",
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


def diagnose(runs: Sequence[pd.DataFrame], baseline: "str | ModelDefinition" = "linear", seed: int = 0,
             group_by: str | None = None, validate: Sequence[pd.DataFrame] = ()) -> dict:
    """Contract JSON: baseline held-out error, findings ordered by gain, leads, best combined model, regimes, evidence.
    `group_by`: the run attribute that groups runs for "the runs disagree on a parameter" (default: every run);
    `validate`: runs no fit sees, where each finding's gain must carry."""
    result = diagnose_runs(runs, baseline, seed=seed, group_by=group_by, validate=validate)
    return summarise(result, result.baseline.spec.name)
