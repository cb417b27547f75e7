"""`benchlab pipeline --out DIR`: the whole job on the simulated bench, end to end (always the simulated bench, by
design: it is the demonstration and the check that everything fits together; each line and page says so).

Runs Table 1 on the simulated bench (the reference clutch by default, docs/plant.md; `--plant paper` the paper's
network), the validation protocol (long hot cool-downs with the engine speed or the clutch state changing, a few fresh
Table 1 cycles, then launches outside Table 1) and the Fig. 3 cool-down sweep; identifies the linear and the nonlinear
model, writes the report (Fig. 3 with the sweep's points, 4, 5, residuals: nonlinear against linear, validated on
the validation run), scores the misfit at the peaks, the unseen load scenarios and the unmeasured plate against the
plant's truth (model and observer), diagnoses the nonlinear model with its page, and estimates wear per side; the
index page opens with a one-line verdict against the paper's figures.

Both runs go through the bench runner (benchlab.runner) and the real drivers talking to the simulated
bench's devices, as on hardware: every reading at the time it was measured, a raw CAN log (BLF) beside
each run file, the validation's heat-ups closed loop ("heat until the flywheel is at 70 °C").
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from benchlab import cliargs
from benchlab.bounds import MAX_RUN_DURATION_S
from benchlab.interrupts import interrupts_held
from benchlab.outputs import check_output_dir, write_text
from benchlab.progress import Progress, for_terminal
from benchlab.provenance import bench_text

if TYPE_CHECKING:
    import pandas as pd

    from benchlab.model.params import ModelParams

NAME = "pipeline"
HELP = ("run Table 1, the validation protocol and the Fig. 3 sweep on the simulated bench, identify, report, diagnose, "
        "estimate wear")
VALIDATION_CYCLES = 3  # Table 1 cycles after the validation protocol's three long cool-downs
#: load scenarios outside Table 1 (engine rpm, clutch N·m, load N·m, cool-down s), after the validation protocol:
#: the paper's "extrapolation for unknown load scenarios"
EXTRAPOLATION = ((2500.0, 80.0, 100.0, 150.0), (800.0, 90.0, 600.0, 150.0), (2500.0, 90.0, 300.0, 150.0))
EXTRAPOLATION_LABEL = "extrapolation"
#: the Fig. 3 points (engine speed and clutch state): four speeds per state, as eq. (11) needs two or more per state
#: beside its shared R0 (benchlab.identify.cooldown.fit_eq11), and the comparison's 1000 and 2500 rpm among them
SWEEP_GRID = "500:1,1000:1,1500:1,2500:1,500:0,1000:0,1500:0,2500:0"
SWEEP_MODEL = "nonlinear-sweep"  # the paper's procedure: eq. (11) from the sweep held, the rest from Table 1
#: diagnose's best model, the nonlinear model fitted on Table 1 and the sweep together with the causes it named
DIAGNOSED_MODEL = "diagnosed"
#: the paper's procedure on the diagnosed structure: eq. (11) from the sweep as that model reads it, held, the rest
#: refitted on Table 1 and the sweep; the model the job's eq. (11) figure is of
HELD_MODEL = "diagnosed-sweep"
DIAGNOSED_RUNS = ("table1", "sweep")  # the runs diagnose fits, in its order


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out", help="directory for run, parameter and report files")
    parser.add_argument("--seed", type=cliargs.seed, default=1, help="seed of the schedule and the bench's noise")
    parser.add_argument("--duration", type=cliargs.positive_float("a duration in s", MAX_RUN_DURATION_S),
                        default=3600.0, help="planned Table 1 duration in s")
    parser.add_argument("--sweep-grid", default=SWEEP_GRID, metavar="RPM:STATE,…",
                        help="the Fig. 3 sweep's cool-down points, as `run cooldown-sweep --grid` takes them (default "
                             f"{SWEEP_GRID}: eq. (11) needs 5 points, 2 speeds per clutch state; the comparison "
                             "reads 1000 and 2500 rpm)")
    parser.add_argument("--plant", choices=("reference", "paper"), default="reference",
                        help="the simulated clutch: the reference plant (default, docs/plant.md) or the paper's network")
    parser.add_argument("--force", action="store_true", help="--out may hold files already (an earlier job's): "
                                                             "replace the ones the job writes")


def _describe(label: str, path: Path, run: pd.DataFrame) -> None:
    print(f"{label:<9} {path}: {len(run)} samples, {run['time'].iloc[-1] / 3600:.2f} h, "
          f"flywheel up to {run['T_flywheel'].max():.1f} degC, on {bench_text(run.attrs.get('bench'))}")


def _bench_run(label: str, path: Path, protocol: str, seed: int, plant: str, progress: Progress,
               **options: object) -> pd.DataFrame:
    """One protocol on the simulated bench through the runner and the real drivers; the run as loaded back."""
    with interrupts_held():  # the runner and the simulator (see benchlab.cli)
        from benchlab.runfile import load_run
        from benchlab.runner.session import RunRequest, execute
        from sim_bench.bench import SimulatedBench
        from sim_bench.reference_plant import plant_named

    code, summary = execute(RunRequest(protocol=protocol, out=path, seed=seed, bench=SimulatedBench(plant_named(plant)),
                                       install_signals=False, progress=progress, **options))
    if code != 0 or summary is None or summary.status != "complete":
        raise RuntimeError(f"{label} run {path} ended {summary.status if summary else 'without a summary'} "
                           f"(exit {code})")
    run = load_run(path)
    _describe(label, path, run)
    return run


def validation_steps(seed: int) -> tuple:
    """The validation protocol (long cool-downs, Table 1 cycles drawn for the simulated bench's drivetrain, so a draw
    whose launch cannot synchronise is drawn again), then cycles with load scenarios Table 1 lacks."""
    from protocols.limits import BenchLimits
    from protocols.schedule import Step
    from protocols.validation import validation_plan

    steps = list(validation_plan(seed, n_cycles=VALIDATION_CYCLES, limits=BenchLimits()).steps)
    cycle = max(s.cycle for s in steps) + 1
    for i, (rpm, torque, load, cool) in enumerate(EXTRAPOLATION):
        steps += [Step("launch", 10.0, rpm, torque, load, cycle + i, label=EXTRAPOLATION_LABEL),
                  Step("drive", cool / 2, rpm, torque, load, cycle + i, label=EXTRAPOLATION_LABEL),
                  Step("open", cool / 2, rpm, 0.0, load, cycle + i, label=EXTRAPOLATION_LABEL)]
    return tuple(steps)


def _diagnose(fitting: pd.DataFrame, sweep: pd.DataFrame, validation: pd.DataFrame, out: Path,
              progress: Progress) -> tuple[dict, ModelParams]:
    """Diagnose the nonlinear model on the Table 1 run and the sweep together (the runs that carry eq. (11), as the
    paper identified it), the validation run unseen: JSON, page with figures, the best model as a model file and a
    parameter file (DIAGNOSED_MODEL), two labelled lines (the unseen gain first); the summary and the best model."""
    with interrupts_held():  # the diagnosis and its page (matplotlib; see benchlab.cli)
        from benchlab.commands.diagnose import best_model, best_values
        from benchlab.diagnose.engine import diagnose_runs
        from benchlab.diagnose.page import write_page
        from benchlab.diagnose.regimes import worst_regimes
        from benchlab.diagnose.report import summarise
        from benchlab.identify.uncertainty import identified_by_runs
        from benchlab.model.definition import to_toml
        from benchlab.model.params import ModelParams, save_params

    diagnosis = diagnose_runs([fitting, sweep], "nonlinear", progress=progress, validate=[validation])
    summary = summarise(diagnosis, "nonlinear")
    write_text(out / "diagnose.json", json.dumps(summary, indent=2, default=float))
    page = write_page(diagnosis, summary, [fitting, sweep], out / "diagnose").with_suffix(".html")
    model = best_model(diagnosis)
    write_text(out / f"{DIAGNOSED_MODEL}.toml", to_toml(model))
    pinned = identified_by_runs(diagnosis.final, diagnosis.final_held.datasets, DIAGNOSED_RUNS)
    diagnosed = ModelParams(model, best_values(diagnosis), {"identified_by": pinned})
    save_params(out / f"{DIAGNOSED_MODEL}.json", diagnosed,
                {"fitted_on": [f"{run}.h5" for run in DIAGNOSED_RUNS], "diagnosis": "diagnose.json"})
    base, best = summary["baseline"], summary["best"]
    found = ", ".join(f"{f['candidate']} ({f['signal']}/{f['mechanism']}, unseen gain {f['unseen_gain_pct']:.0f} %, "
                      f"held-out {f['gain_pct']:.0f} %)" for f in summary["findings"]) or "none"
    leads = "".join(f"; lead {f['candidate']}: {'; '.join(f['reasons'])}" for f in summary["leads"])
    unseen = best["unseen"]
    print(f"diagnose  nonlinear baseline -> best {best['model']}: validation run (unseen) {unseen['rmse_before_K']:.3f} "
          f"-> {unseen['rmse_after_K']:.3f} K, held-out {base['rmse_K']:.3f} -> {best['rmse_K']:.3f} K; "
          f"findings: {found}{leads}")
    worst = worst_regimes(summary["regimes"]["baseline"], 1)
    if worst:
        group, label, channel, rmse, _ = worst[0]
        print(f"          worst regime (held-out): {group} = {label}, {channel} {rmse:.3f} K -> {page}")
    print(f"          the best model, fitted on Table 1 and the sweep -> {out / (DIAGNOSED_MODEL + '.json')} "
          f"(model file {out / (DIAGNOSED_MODEL + '.toml')})")
    groups: dict[str, list[str]] = {}
    for name, runs in pinned.items():
        groups.setdefault(" and ".join(runs) if runs else "none of the runs", []).append(name)
    print("          identified by: " + "; ".join(f"{runs}: {', '.join(names)}" for runs, names in groups.items()))
    return summary, diagnosed


def _alternatives(diagnosis: dict, diagnosed: "ModelParams", nonlinear: dict) -> tuple:
    """Diagnose's best model as a second structure for the plate's band where it predicts the validation run (its
    measured channels, no truth) at least as well as the nonlinear model: two structures that fit alike and
    disagree on the plate are a doubt the band must carry; a worse one is no alternative."""
    after = (diagnosis.get("best", {}).get("unseen") or {}).get("rmse_after_K", math.inf)
    return (diagnosed,) if after <= nonlinear["validation"]["rmse_K"] else ()


def _plate(run: pd.DataFrame, path: Path, nonlinear, model: pd.DataFrame, alternatives: tuple = (),
           flywheel_miss_k: float = 0.0, plate_relative: float | None = None):
    """The unmeasured plate on a run: the model's simulation and the observer's estimate (flywheel, air and housing
    sensors; its band widened by the model-form spread, benchlab.observer.spread: the nonlinear model's parameter
    draws, the spread across it and the `alternatives`, structures that fit as well, and `plate_relative`, the
    sweep's reading of the plate against the model's, start_discrepancy) against /truth, with the
    wear per side over the band (the measured flywheel's widened by `flywheel_miss_k`, the model's miss on it while
    slipping on the unseen run); None where the run has no truth."""
    with interrupts_held():
        import numpy as np

        from benchlab.observer.batch import observe
        from benchlab.observer.spread import combined, discrepancy_spread, form_spread, model_spread, widened
        from benchlab.report.showcase import PLATE, plate_band, plate_check
        from benchlab.runfile import load_truth
        from benchlab.wear import default_clutch

    truth = load_truth(path)
    if truth is None:
        return None
    spread = model_spread(run, nonlinear, [PLATE])
    if alternatives:
        spread = combined(spread, form_spread(run, [nonlinear, *alternatives], [PLATE]))
    if plate_relative is not None:
        spread = combined(spread, discrepancy_spread(model[PLATE], float(np.nanmedian(run["T_ambient"])),
                                                     plate_relative))
    observed = widened(observe(run, nonlinear, ["T_flywheel", "T_air", "T_housing"]), spread)
    estimates = {"model": model[PLATE].to_numpy(), "observer": observed.estimate[PLATE].to_numpy()}
    return plate_check(run, truth, estimates, model, plate_band(run, truth, observed, model, nonlinear,
                                                                default_clutch(), flywheel_miss_k))


def _sweep_comparison(fitting: pd.DataFrame, validation: pd.DataFrame, sweep: pd.DataFrame, nonlinear, out: Path,
                      figures: dict, progress: Progress):
    """Eq. (11) as the sweep measures it against the Table 1 model, and the paper's procedure (eq. (11) from the sweep,
    the rest refitted on Table 1) saved as its own parameter file and scored beside the others."""
    with interrupts_held():
        from benchlab.identify.staged import COMPARED_RPM, compare_with_sweep
        from benchlab.model.params import save_params

    comparison = compare_with_sweep([fitting], nonlinear, out / "sweep.h5", validate=[validation], progress=progress,
                                    sweep_run=sweep)
    speeds = " and ".join(f"{s:.0f}" for s in COMPARED_RPM)
    print(f"eq. (11)  the Table 1 model's R(engine speed, clutch state) lies up to {100 * comparison.rel_error:.0f} % "
          f"from the sweep's cool-downs at {speeds} rpm")
    if comparison.sweep_model is not None:
        result = comparison.sweep_model
        save_params(out / f"{SWEEP_MODEL}.json", result.params, result.summary())
        fit_fig, val_fig = next(iter(result.fitting.values())), next(iter(result.validation.values()))
        figures[SWEEP_MODEL] = {"fit": fit_fig, "validation": val_fig}
        print(f"identify  {SWEEP_MODEL}: eq. (11) from the sweep, the rest from Table 1: fit RMSE "
              f"{fit_fig['rmse_K']:.3f} K, validation RMSE {val_fig['rmse_K']:.3f} K -> {out / (SWEEP_MODEL + '.json')}")
    return comparison


def _eq11_errors(comparison, fitting: pd.DataFrame, sweep: pd.DataFrame, validation: pd.DataFrame,
                 diagnosed: "ModelParams", out: Path, figures: dict, progress: Progress
                 ) -> tuple[dict[str, float], "ModelParams | None"]:
    """Each model's eq. (11) against the sweep's points: the Table 1 model and the paper's procedure against the
    points read with the Table 1 model, the model identified with the sweep (DIAGNOSED_MODEL) and the paper's
    procedure on its structure (HELD_MODEL, saved and scored beside the others) against the points each reads with
    its own structure and values (benchlab.identify.staged); the errors and HELD_MODEL's parameters (None where the
    points cannot determine eq. 11)."""
    with interrupts_held():
        from benchlab.identify.staged import COMPARED_RPM, eq11_rel_error, held_to_own_points, own_points_error
        from benchlab.model.params import save_params

    errors = {"nonlinear": comparison.rel_error}
    if comparison.sweep_model is not None:
        errors[SWEEP_MODEL] = eq11_rel_error(comparison.sweep_model.params, comparison.points)
    points, errors[DIAGNOSED_MODEL] = own_points_error(out / "sweep.h5", diagnosed, progress, sweep_run=sweep)
    held = held_to_own_points([fitting, sweep], diagnosed, out / "sweep.h5", points, validate=[validation],
                              progress=progress, sweep_run=sweep)
    speeds = " and ".join(f"{s:.0f}" for s in COMPARED_RPM)
    print(f"eq. (11)  the model identified with the sweep ({DIAGNOSED_MODEL}) lies up to "
          f"{100 * errors[DIAGNOSED_MODEL]:.0f} % from the sweep's points as it reads them, at {speeds} rpm "
          f"(the Table 1 model {100 * errors['nonlinear']:.0f} %)")
    if held is None:
        return errors, None
    result, errors[HELD_MODEL] = held
    save_params(out / f"{HELD_MODEL}.json", result.params, result.summary())
    fitted = list(result.fitting.values())  # Table 1 and the sweep: their RMS, as one fit's figure
    fit_fig = {"rmse_K": math.sqrt(sum(f["rmse_K"] ** 2 for f in fitted) / len(fitted)),
               "nrmse_pct": sum(f["nrmse_pct"] for f in fitted) / len(fitted)}
    val_fig = next(iter(result.validation.values()))
    figures[HELD_MODEL] = {"fit": fit_fig, "validation": val_fig}
    print(f"identify  {HELD_MODEL}: its structure with eq. (11) from the sweep as it reads it, the rest from Table 1 "
          f"and the sweep: eq. (11) {100 * errors[HELD_MODEL]:.0f} % from its points, validation RMSE "
          f"{val_fig['rmse_K']:.3f} K -> {out / (HELD_MODEL + '.json')}")
    return errors, result.params


def _deploy(validation: pd.DataFrame, nonlinear: "ModelParams", out: Path) -> dict | None:
    """The nonlinear model's observer and wear as a float C module in `out/deploy`, proven on the validation run
    (docs/deploy.md); None, said in one line, where the machine has no C compiler."""
    import shutil

    from benchlab.deploy.module import prove, write_module
    from benchlab.deploy.plan import make_plan
    from benchlab.wear import default_clutch

    if shutil.which("cc") is None:
        print("deploy    skipped: no C compiler (cc) on this machine")
        return None
    plan = make_plan(nonlinear, ["T_air"], float(validation.attrs["dt"]), default_clutch())
    proof = prove(plan, [validation], "float")
    write_module(out / "deploy", plan, "float", proof)
    write_text(out / "deploy" / "verify.json", json.dumps(proof, indent=1) + "\n")
    print(f"deploy    {plan.name} (float C): largest deviation from the observer over the validation run "
          f"{max(proof['max_abs_dev_K'].values()):.2g} K, plate σ {proof['plate_sigma_rel_dev']:.2g}, wear "
          f"{proof['wear_rel_dev']:.2g} (relative); state {proof['state_bytes']} B, code {proof['code_bytes']} B, "
          f"{proof['step_us']:.2f} µs per step -> {out / 'deploy' / 'README.md'}")
    return {"module": plan.name, **proof}


def finite_or_null(value: object) -> object:
    """JSON-safe: a figure the job could not measure (NaN) becomes null, recursively."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def _unseen_rmse(best: dict, key: str) -> float:
    """The diagnosis's RMSE on the validation run (its baseline's or its best model's), NaN without one."""
    unseen = best.get("unseen") or {}
    return float(unseen[key]) if key in unseen else math.nan


def job_figures(figures: dict, story: dict, cooldowns, eq11_errors: dict[str, float], diagnosis: dict,
                diagnosed: "ModelParams") -> dict:
    """DIR/summary.json: the figures the verdict holds against the paper's and the issue's references, NaN where
    the job could not measure one (no truth, no finding); the long cool-downs' figure is the best model's, eq. (11)'s
    that of the model identified with the sweep by the paper's procedure (HELD_MODEL; DIAGNOSED_MODEL where the
    points could not determine eq. 11), each model's beside it."""
    from benchlab.report.index import mean_cooldown_nrmse

    nonlinear = figures["nonlinear"]

    plate = story["plate"]
    by_model = {m: mean_cooldown_nrmse(cooldowns, m) for m in (cooldowns[0].nrmse_pct if cooldowns else ())}
    flywheel = {m: mean_cooldown_nrmse(cooldowns, m, flywheel=True) for m in by_model}
    best_cooling = min(by_model, key=by_model.get) if by_model else None
    best = diagnosis.get("best", {})
    unseen_gain = best.get("unseen_gain_pct")
    eq11_model = HELD_MODEL if HELD_MODEL in eq11_errors else DIAGNOSED_MODEL
    findings = diagnosis.get("findings", [])
    return {"causes": [f["candidate"] for f in findings if f.get("label", "cause") == "cause"],
            "patches": [f["candidate"] for f in findings if f.get("label") == "patch"],
            "leads": [f["candidate"] for f in diagnosis.get("leads", [])],
            "unseen_gain_pct": float(unseen_gain) if unseen_gain is not None else math.nan,
            "diagnosed_runs": list(DIAGNOSED_RUNS), "identified_by": diagnosed.extra["identified_by"],
            "validation_rmse_k_by_model": {"nonlinear": float(nonlinear["validation"]["rmse_K"]),
                                           "nonlinear (Table 1 and sweep)": _unseen_rmse(best, "rmse_before_K"),
                                           DIAGNOSED_MODEL: _unseen_rmse(best, "rmse_after_K"),
                                           **({HELD_MODEL: float(figures[HELD_MODEL]["validation"]["rmse_K"])}
                                              if HELD_MODEL in figures else {})},
            "in_run_gain_pct": float(diagnosis["findings"][0]["gain_pct"]) if diagnosis.get("findings") else math.nan,
            "fit_nrmse_pct": float(nonlinear["fit"]["nrmse_pct"]),
            "validation_nrmse_pct": float(nonlinear["validation"]["nrmse_pct"]),
            "cooldown_nrmse_pct": by_model[best_cooling] if best_cooling else math.nan,
            "cooldown_best_model": best_cooling, "cooldown_nrmse_pct_by_model": by_model,
            "cooldown_flywheel_nrmse_pct": flywheel[best_cooling] if best_cooling else math.nan,
            "peak_pct": max(story["peaks"][k]["nonlinear"].max_pct for k in story["peaks"]),
            "eq11_rel_error": eq11_errors[eq11_model], "eq11_rel_error_pct": 100.0 * eq11_errors[eq11_model],
            "eq11_model": eq11_model, "eq11_rel_error_by_model": eq11_errors,
            "plate_rmse_k": plate.rmse_k["observer"] if plate is not None else math.nan,
            "plate_band_coverage": plate.band_coverage if plate is not None else math.nan,
            "plate_band_half_width_k": plate.band.half_width_k if plate is not None and plate.band else math.nan}


def run(args: argparse.Namespace) -> int:
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        import numpy as np

        from benchlab.identify.api import identify
        from benchlab.identify.identifiability import recorded
        from benchlab.model.params import load_params, save_params
        from benchlab.report import write_report
        from benchlab.report.index import cooldown_scores, mean_cooldown_nrmse, write_index
        from benchlab.report.resistance import standard_errors
        from benchlab.report.scores import estimate
        from benchlab.observer.spread import slipping_residual, start_discrepancy
        from benchlab.report.showcase import FLYWHEEL, PLATE, labelled_mask, peak_misfit, scores_on, verdict
        from benchlab.wear import analyse_wear
        from benchlab.wear.plot import plot_wear

    progress = for_terminal(args.quiet)
    out = check_output_dir(args.out, "--out", args.force)
    out.mkdir(exist_ok=True)
    runs = ("table1", "validation", "sweep")
    for stale in [*(out / f"{r}.h5" for r in runs), *(p for r in runs for p in out.glob(f"{r}*.blf"))]:
        stale.unlink(missing_ok=True)  # the job writes its runs anew each time
    fitting = _bench_run("run", out / "table1.h5", "table1", args.seed, args.plant, progress, duration_s=args.duration)
    validation = _bench_run("validation", out / "validation.h5", "validation", args.seed + 1, args.plant, progress,
                            steps=validation_steps(args.seed + 1))
    sweep = _bench_run("sweep", out / "sweep.h5", "cooldown-sweep", args.seed + 2, args.plant, progress,
                       grid=args.sweep_grid)
    figures = {}
    for model in ("linear", "nonlinear"):
        result = identify([fitting], model, validate=[validation], starts=4, progress=progress)
        save_params(out / f"{model}.json", result.params, result.summary())
        fit_fig, val_fig = next(iter(result.fitting.values())), next(iter(result.validation.values()))
        figures[model] = {"fit": fit_fig, "validation": val_fig}
        print(f"identify  {model:9s}: fit RMSE {fit_fig['rmse_K']:.3f} K ({fit_fig['nrmse_pct']:.2f} %), "
              f"validation RMSE {val_fig['rmse_K']:.3f} K ({val_fig['nrmse_pct']:.2f} %) -> {out / (model + '.json')}")
    nonlinear, linear = load_params(out / "nonlinear.json"), load_params(out / "linear.json")
    comparison = _sweep_comparison(fitting, validation, sweep, nonlinear, out, figures, progress)
    diagnosis, diagnosed = _diagnose(fitting, sweep, validation, out, progress)
    eq11_errors, held = _eq11_errors(comparison, fitting, sweep, validation, diagnosed, out, figures, progress)
    alternatives = _alternatives(diagnosis, diagnosed, figures["nonlinear"])
    models = {"linear": linear, "nonlinear": nonlinear}
    sims = {run_label: {m: estimate(r, p, m).simulated for m, p in models.items()}
            for run_label, r in (("fit", fitting), ("validation", validation))}
    flywheel_miss = slipping_residual(validation, sims["validation"]["nonlinear"], FLYWHEEL)
    plate_relative = start_discrepancy(comparison.points, sweep["time"].to_numpy(),
                                       estimate(sweep, nonlinear, "nonlinear").simulated[PLATE].to_numpy(),
                                       float(np.nanmedian(sweep["T_ambient"])))
    unseen = labelled_mask(validation, out / "validation.h5", EXTRAPOLATION_LABEL)
    table1 = labelled_mask(validation, out / "validation.h5", "table1")
    story = {"peaks": {run_label: {m: peak_misfit(r, sims[run_label][m]) for m in models}
                       for run_label, r in (("fit", fitting), ("validation", validation))},
             "extrapolation": {"Table 1 cycles": scores_on(validation, table1, sims["validation"]),
                               "load scenarios not in Table 1": scores_on(validation, unseen, sims["validation"])},
             "plate": _plate(validation, out / "validation.h5", nonlinear, sims["validation"]["nonlinear"],
                             alternatives, flywheel_miss, plate_relative)}
    for m in models:
        worst = max(story["peaks"][k][m].max_pct for k in ("fit", "validation"))
        print(f"misfit    {m:9s}: peaks up to {worst:.1f} % (paper: 5 %), unseen load scenarios "
              f"{story['extrapolation']['load scenarios not in Table 1'][m]:.2f} K RMSE (Table 1 cycles "
              f"{story['extrapolation']['Table 1 cycles'][m]:.2f} K)")
    if story["plate"] is not None:
        plate = story["plate"]
        print(f"plate     against /truth: model RMSE {plate.rmse_k['model']:.2f} K, observer "
              f"{plate.rmse_k['observer']:.2f} K; plate hotter than the flywheel while slipping by "
              f"{plate.hotter_truth_k:.2f} K (truth), {plate.hotter_model_k:.2f} K (model)")
        spread_text = ", ".join(["parameter draws"] + ([f"the {DIAGNOSED_MODEL} model's plate"] if alternatives else [])
                                + ([f"the sweep's reading of the plate, {100 * plate_relative:.0f} % of the model's "
                                    f"rise above ambient"] if plate_relative is not None else []))
        print(f"          observer's ±2σ band (model-form spread: {spread_text}) covers the truth "
              f"{100 * plate.band.plate_band_coverage:.1f} % of the samples, mean half-width "
              f"{plate.band.half_width_k:.2f} K (filter alone {plate.band.filter_half_width_k:.2f} K)")
        if plate.band.observer_note:
            print(f"          note: {plate.band.observer_note}")
    page = write_report(fitting, nonlinear, out / "report", compare=linear, validation=[validation],
                        sweep=out / "sweep.h5", progress=progress, sweep_fitted=comparison.points)
    print(f"report    nonlinear against linear, validated on {out / 'validation.h5'}, Fig. 3 measured on "
          f"{out / 'sweep.h5'} -> {page.with_suffix('.html')}")
    wear_report = analyse_wear(fitting, nonlinear)
    wear = wear_report.as_dict()
    story["wear_band"] = _plate(fitting, out / "table1.h5", nonlinear, sims["fit"]["nonlinear"], alternatives,
                                flywheel_miss, plate_relative)
    if story["wear_band"] is not None:
        wear["from_observer"] = story["wear_band"].band.as_dict()["wear_mm"]
        wear["flywheel_miss_K"] = flywheel_miss
    write_text(out / "wear.json", json.dumps(wear, indent=2, default=float))
    plot_wear(wear_report, out / "wear.png")
    print(f"wear      {wear['engagements']} engagements, {wear['friction_energy_J'] / 1e6:.2f} MJ -> {out / 'wear.json'}")
    if "from_observer" in wear:
        print(f"          the flywheel's band widened by the model's {flywheel_miss:.2f} K RMS miss on its sensor while "
              f"slipping on the validation run (the sensor reads behind the friction face)")
    for side, values in wear.get("from_observer", {}).items():
        print(f"          {side} side at the observer's estimate {1000 * values['estimate']:.4f} µm, over its ±2σ band "
              f"{1000 * values['low']:.4f}-{1000 * values['high']:.4f} µm; at the truth {1000 * values['truth']:.4f} µm")
    story["deploy"] = _deploy(validation, nonlinear, out)
    compared = [("linear", linear), ("nonlinear", nonlinear)]
    if comparison.sweep_model is not None:
        compared.append((SWEEP_MODEL, comparison.sweep_model.params))
    compared.append((DIAGNOSED_MODEL, diagnosed))
    if held is not None:
        compared.append((HELD_MODEL, held))
    cooldowns = cooldown_scores(validation, out / "validation.h5", compared)
    for label, _ in compared:
        print(f"cool-down {label:9s}: long cool-downs of the validation run, mean NRMSE "
              f"{mean_cooldown_nrmse(cooldowns, label):.1f} % (paper: nonlinear 3.8 %, linear 8.4 %), the flywheel "
              f"alone {mean_cooldown_nrmse(cooldowns, label, flywheel=True):.1f} %")
    figures_held = job_figures(figures, story, cooldowns, eq11_errors, diagnosis, diagnosed)
    figures_held["not_identified"] = recorded(nonlinear)
    figures_held["plate_sweep_discrepancy"] = plate_relative if plate_relative is not None else math.nan
    story["diagnosed_runs"], story["identified_by"] = figures_held["diagnosed_runs"], figures_held["identified_by"]
    story["verdict"] = figures_held["verdict"] = verdict(figures_held)
    print(f"verdict   {story['verdict']}")
    write_text(out / "summary.json", json.dumps(finite_or_null(figures_held), indent=2))
    runs_shown = {"Table 1": (out / "table1.h5", fitting), "validation": (out / "validation.h5", validation),
                  "Fig. 3 sweep": (out / "sweep.h5", sweep)}
    index = write_index(out, runs_shown,
                        figures, cooldowns, nonlinear, standard_errors(nonlinear), diagnosis, wear, story)
    print(f"page      the whole job -> {index}")
    return 0
