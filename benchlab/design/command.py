"""What `benchlab design` does once its command line is read: runs and parameter file in, plan file out."""

from __future__ import annotations

import argparse
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from benchlab.design.blocks import Block, candidate_blocks, steady_blocks, steady_schedule
from benchlab.design.fisher import predicted_run
from benchlab.design.points import branch_states, determines, operating_point, read_runs
from benchlab.design.precision import design_cooldown_reading, design_precision
from benchlab.identify.cooldown import segment_model
from benchlab.identify.staged import EQ11
from benchlab.design.sensors import rank_sensors
from benchlab.errors import InputError, read_document
from benchlab.identify.data import prepare
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.model.catalog import model_spec
from benchlab.model.params import ModelParams, load_params
from benchlab.model.runs import load_runs
from benchlab.network.plant import NetworkPlant, unplayable
from benchlab.outputs import write_text
from benchlab.runner.session import RunRequest, bench_config
from protocols.estimates import Plant
from protocols.limits import BenchLimits
from protocols.schedule import duration_s


def nominal_values(params: ModelParams, open_: Mapping[str, str]) -> dict[str, float]:
    """The values the design predicts with: the fitted ones, and for each parameter the runs leave open the model
    file's start value (a fit's value of it is arbitrary: often on a bound, where it has no effect to design for)."""
    starts = {p.name: p.start for p in params.definition.free_parameters()}
    return {n: (starts[n] if n in open_ and n in starts else v) for n, v in params.items()}


def model_error_warnings(fit: object) -> list[str]:
    """What the parameter file's residual tests say against the design's first assumption (the model is right):
    one line where a run's residuals hold structure beyond the tests' effect size."""
    residuals = fit.get("residuals") if isinstance(fit, dict) else None
    if not isinstance(residuals, dict):
        return []
    found = [(float(tests["structure_K"]), run, channel) for run, channels in residuals.items()
             if isinstance(channels, dict) for channel, tests in channels.items()
             if isinstance(tests, dict) and tests.get("white") is False and isinstance(tests.get("structure_K"),
                                                                                       (int, float))]
    if not found:
        return []
    structure, run, channel = max(found)
    return [f"the model leaves {structure:.3f} K of structure in the residuals ({channel} of {run}; "
            f"{len(found)} channel(s) not white): the expected errors assume the model is right, and a fit of the "
            "designed run may bend other parameters instead (benchlab diagnose says what the model misses)"]


def checked_budget(budget_min: float, limits: BenchLimits, blocks: Sequence[Block] | None = None) -> float:
    """The budget in s, or InputError where it is shorter than the shortest of `blocks` (default the launch
    blocks) on this bench."""
    shortest = min((b.expected_s for b in (candidate_blocks(limits) if blocks is None else blocks)), default=np.inf)
    if budget_min * 60.0 < shortest:
        raise InputError("command line", "--budget", f"at least {np.ceil(shortest / 60):g} min: the shortest block "
                                                     f"(heat, then a cool-down) lasts {shortest / 60:.1f} min on "
                                                     f"this bench, got {budget_min:g}")
    return budget_min * 60.0


def reading_min(blocks: Sequence[Block], interest: Sequence[str], limits: BenchLimits, plant: Plant) -> float:
    """Minutes the shortest plan the cool-down reading can read eq. (11)'s branches that `interest` lies in from
    lasts (`points.determines`: three engine speeds in each such clutch state and one point more), timed in
    sequence on `plant`."""
    chosen: list[Block] = []
    for state in sorted(branch_states(interest)):
        own = sorted((b for b in blocks if operating_point(b)["clutch_state"] == state), key=lambda b: b.expected_s)
        chosen += own[:3]
    chosen.append(min(chosen, key=lambda b: b.expected_s))
    return duration_s(steady_schedule(chosen, limits, plant)) / 60.0


def design(args: argparse.Namespace, schema: str) -> int:
    """Read, check, design, print the expected outcome, write the plan (docs/design.md)."""
    params = load_params(args.params)
    spec = model_spec(params.definition)
    problem = unplayable(spec.network)  # a designed run is predicted and timed by a plant, chunk by chunk
    if problem:
        raise InputError(args.params, "model", problem)
    names = [p.name for p in spec.free]
    open_ = params.extra.get("not_identified") or {}
    if not isinstance(open_, dict):
        raise InputError(args.params, "not_identified", "an object of parameter -> reason")
    interest = [n for n in names if n in open_]
    if args.parameters:
        interest = [n.strip() for n in args.parameters.split(",") if n.strip()]
        unknown = [n for n in interest if n not in names]
        if unknown or not interest:
            raise InputError("command line", "--parameters", f"free parameters of the model ({', '.join(names)}), "
                                                             f"got {args.parameters!r}")
    if not interest:
        raise InputError(args.params, "not_identified", "at least one parameter of the model the runs leave open "
                                                        "(every parameter is identified: name some with --parameters)")
    nominal = nominal_values(params, open_)
    limits = bench_config(RunRequest(protocol="design", out=Path(args.out), bench=args.bench)).limits
    reading = args.reading  # the designed run's cool-downs read one by one (docs/design.md)
    if reading and not set(interest) <= set(EQ11):
        raise InputError("command line", "--reading", f"parameters of eq. (11) only ({', '.join(EQ11)}) to design "
                                                      f"for, got {', '.join(interest)}")
    steady: list[Block] = []
    if reading:
        free = {p.name: p for p in params.definition.free_parameters()}
        read = read_runs(args.runs, dict(params.items()), {n: free[n].start for n in EQ11},
                         {n: (free[n].min, free[n].max) for n in EQ11}, interest, segment_model(params))
        nominal.update(read.values)
        plant = NetworkPlant(spec.network, dict(params.items()))  # times and checks them: the runs' own fit
        steady = steady_blocks(limits, plant)
    budget_s = checked_budget(args.budget, limits, steady if reading else None)
    runs = load_runs(args.runs, params.definition, nominal, str(args.params))
    data = [prepare(run, FIT_STEP_S, name=f"run{i}", network=spec.network) for i, run in enumerate(runs)]
    ambient = float(np.nanmean(runs[-1]["T_ambient"].to_numpy()))
    reported = params.extra.get("uncertainty") or {}
    identified = [n for n in names if n not in open_]
    try:
        if reading:
            fit = params.extra.get("fit") if isinstance(params.extra.get("fit"), dict) else {}
            before = {n: np.inf if n in open_ or not params[n] else float(reported.get(n, np.inf)) / abs(params[n])
                      for n in interest}
            try:
                plan = design_cooldown_reading(spec.network, nominal, names, interest, data, before,
                                               fit.get("fitting") or {}, read, limits, ambient,
                                               budget_s, steady, plant, segment_model(params))
                reading = determines(plan.blocks, interest)
            except ValueError:  # no steady block fits: the joint design says whether any block does
                reading = False
            if not reading:
                print(f"--reading: the budget holds too few steady cool-downs to read eq. (11) from (three engine "
                      f"speeds in the clutch state designed for and one point more take "
                      f"{reading_min(steady, interest, limits, plant):.0f} min): designed for the joint fit "
                      "instead")
                nominal = nominal_values(params, open_)
        if not reading:
            plan = design_precision(spec.network, nominal, names, interest, identified, data, reported, limits,
                                    ambient, budget_s)
    except ValueError as exc:  # no block the bench's interlocks allow: the bench's limits are the input at fault
        raise InputError(args.bench, "limits", f"room for one block of heating and cooling ({exc})") from None
    moved = ", ".join(f"{n} {nominal[n]:.4g}" for n in names if n in open_ and not (reading and n in EQ11))
    if moved:
        print(f"not identified, taken at the model file's start values: {moved}")
    if reading:
        print("eq. (11) taken as the runs' held stretches read as cool-downs give it (b: the model file's), their "
              f"points {plan.disagreement:.2f} x their errors off it, those at one operating point "
              f"{100 * plan.scatter:.1f} % of R apart beyond their errors: "
              + ", ".join(f"{n} {nominal[n]:.4g}" for n in EQ11))
    print("\n".join(plan.lines(nominal)))
    warnings = model_error_warnings(params.extra.get("fit"))
    for line in warnings:
        print(f"warning: {line}")
    predicted = predicted_run(plan.steps, nominal, spec.network, ambient, limits.drivetrain)
    sensors = rank_sensors(predicted, nominal, spec.network, names, interest, plan.prior, plan.noise)
    print("a sensor at each place, on the designed run (what it removes of the plate's estimate variance, what it "
          "adds to the information):")
    print("\n".join(s.line() for s in sensors))
    doc = {"schema": schema, "kind": "precision", "identification": plan.identification,
           "model": params.definition.label,
           "params_file": str(args.params), "runs": [str(r) for r in args.runs], "bench": str(args.bench),
           "budget_min": args.budget, "planned_min": round(sum(s.expected_s for s in plan.steps) / 60, 2),
           "blocks": [b.name for b in plan.blocks],
           "expected": {n: {"value": nominal[n], "relative_error_now": plan.before[n],
                            "relative_error_expected": plan.expected[n]} for n in interest},
           "calibration": plan.calibration,
           **({"disagreement": plan.disagreement, "scatter": plan.scatter} if reading else {}),
           "ambient_C": ambient,
           "sensors": [asdict(s) for s in sensors], "warnings": warnings,
           "schedule": [s.as_dict() for s in plan.steps]}
    write_text(args.out, json.dumps(doc, indent=1) + "\n")
    print(f"plan       {args.out}")
    return 0


def discriminate(args: argparse.Namespace, schema: str) -> int:
    """Read the diagnosis and runs, refit the two contenders, design, print the expected outcome, write the plan."""
    from benchlab.design.discrimination import design_discrimination
    from benchlab.design.rivals import baseline_model, contest, refitted_rivals
    from benchlab.design.sensors import rank_discriminating_sensors

    if args.parameters:
        raise InputError("command line", "--parameters", "--params (a discrimination design has no parameters of "
                                                          "interest: it tells two models apart)")
    doc = read_document(args.diagnosis, "diagnose JSON", json.loads, (ValueError,), "a JSON object")
    model = baseline_model(contest(doc, args.diagnosis), args.diagnosis)  # refused before the runs are read
    limits = bench_config(RunRequest(protocol="design", out=Path(args.out), bench=args.bench)).limits
    budget_s = checked_budget(args.budget, limits)
    runs = load_runs(args.runs, model)
    favoured, other, data = refitted_rivals(doc, args.diagnosis, runs)
    ambient = float(np.nanmean(runs[-1]["T_ambient"].to_numpy()))
    try:
        plan = design_discrimination(favoured, other, data, limits, ambient, budget_s)
    except ValueError as exc:
        raise InputError(args.bench, "limits", f"room for one block of heating and cooling ({exc})") from None
    print("\n".join(plan.lines()))
    sensors = rank_discriminating_sensors(favoured, other, plan, ambient, limits)
    print("a sensor at each place, on the designed run (what it removes of the plate's estimate variance, what it "
          "adds to the test between the two):")
    print("\n".join(s.line() for s in sensors))
    out = {"schema": schema, "kind": "discrimination", "model": doc["baseline"]["model"],
           "diagnosis_file": str(args.diagnosis), "runs": [str(r) for r in args.runs], "bench": str(args.bench),
           "budget_min": args.budget, "planned_min": round(sum(s.expected_s for s in plan.steps) / 60, 2),
           "blocks": [b.name for b in plan.blocks],
           "expected": {"favoured": plan.favoured, "loser": plan.other, "rmse_gap_K": plan.expected.rmse_gap,
                        "rms_difference_K": plan.rms_difference, "misfit_K": plan.noise,
                        "statistic": plan.statistic, "statistic_now": plan.statistic_now, "p_value": plan.p_value,
                        "block_t": plan.expected.block_t, "block_p": plan.expected.block_p,
                        "blocks": plan.expected.blocks, "floor_ratio": plan.floor_ratio,
                        "plant_may_be_neither": plan.neither},
           "ambient_C": ambient, "sensors": [asdict(s) for s in sensors],
           "schedule": [s.as_dict() for s in plan.steps]}
    write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(f"plan       {args.out}")
    return 0
