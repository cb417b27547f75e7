"""Cool-down analysis of a cooldown-sweep run: R_FA = R_PA per operating point, then the fit of eq. (11).

Each cool-down segment (events `cooldown_start`/`cooldown_end`) is fitted with the paper's 4-state model
(eq. 6-9, the linear clutch model file: one resistance R0 = R) driven by the measured inputs: the convection resistance R
(constant during the segment) and the unmeasured initial pressure-plate temperature ϑ_P(0) are free, every
other parameter comes from a parameter file identified beforehand (e.g. from a Table 1 run). The initial
flywheel, air and housing temperatures are free too (started at their first measured values): a single
noisy first sample would otherwise bias R by many standard errors. The single-exponential shortcut (fit
ϑ_F = ϑ_∞ + Δ·exp(−t/τ), R = τ/C_F) is biased because ϑ_P ≠ ϑ_F and the air warms and cools with them.

Residuals are the measured T_flywheel and T_air minus the model at the readings' own times (the first
grid sample of each new reading: a held sample is an old reading), at most one per `sample_s`, weighted
by each channel's noise, which is estimated from the measured signal itself (differences of consecutive
readings). The standard error
of R comes from the Jacobian at the optimum, scaled by the reduced chi-square when it exceeds 1. The
stated uncertainty is the expanded one, U = 2·sqrt(SE² + (0.25 %·R)²) (about 95 %), the second term for
the acquisition's own systematic effects (see SYSTEMATIC_REL).

Eq. (11): R = a1·exp(b1·ω_e) + R0 for S = 1 and a2·exp(b2·ω_e) + R0 for S = 0, fitted to the table by
weighted least squares. Where the points scatter about it beyond their own errors (a reduced chi-square above 1),
each point also carries a between-reading scatter, a share s of its R: a reading depends on the plant's states it
does not fit (the slow masses the model lacks, as warm as the run's history left them), which no segment's own
residuals show. s is the Paule–Mandel estimate (the share that brings the reduced chi-square to 1, the standard
random-effects estimator), the weights 1/(SE² + (s·R)²), the standard errors those of that fit.

Each cool-down's operating point is its step's `point` in the run's stored schedule (/schedule); the table and
the fit are stored in /analysis and read back from there (benchlab.runfile.analysis).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.optimize

from benchlab.model.build import build_network
from benchlab.model.clutch import clutch_network, convection_resistance
from benchlab.model.definition import ModelDefinition
from benchlab.errors import InputError
from benchlab.identify.metrics import robust_sigma
from benchlab.progress import SILENT, Progress, Task
from benchlab.runfile import (Event, load_analysis, load_attrs, load_events, load_run, load_schedule,
                              write_analysis, write_analysis_file)
from benchlab.runfile.schema import END_CONDITION, END_TIME
from benchlab.network.sensors import reading, temperature_of
from benchlab.network.simulation import initial_state, input_channels
from benchlab.network.solver import run_network
from protocols.schedule import Step

COVERAGE_K = 2.0
#: Relative standard uncertainty of R from the acquisition itself (held samples, time stamps of batched
#: readings, command latency, start of the segment), found on the simulated bench: over 58 cool-downs
#: (two grids, 5-6 seeds) the statistical SE alone left |error| > 2 SE three times.
SYSTEMATIC_REL = 0.0025
FIT_CHANNELS = ("T_flywheel", "T_air", "T_housing")
INIT_S = 10.0  # initial measured states: a straight line through the first INIT_S of readings
COOLDOWN_LABEL = "cooldown"  # the schedule's label of a cool-down step (protocols/cooldown_sweep.py)
METHOD = "4-state model, R and T_P0 free"  # how the stored table was fitted (/analysis/cooldowns attribute)


@dataclass
class CooldownResult:
    """One cool-down's row of the table (/analysis/cooldowns: benchlab.runfile.schema.COOLDOWN_UNITS)."""

    cycle: int
    engine_speed: float
    clutch_state: int
    slip_speed: float
    t_start: float
    t_end: float
    R: float
    R_se: float
    R_u: float
    T_P0: float
    T_P0_se: float
    rmse_K: float
    n: int
    chi2_red: float
    R_true: float = math.nan


def segments(path: "str | os.PathLike[str]") -> list[tuple[int, float, float, dict[str, float]]]:
    """(cycle, t_start, t_end, point) of every completed cool-down of the run (its `cooldown_end`'s reason: the
    step's condition was met, or its time ran out on a cool-down of fixed length, one without a condition: a
    designed run's, docs/design.md).

    The times are the `cooldown_start`/`cooldown_end` events'; the operating point is that of the step in the
    stored schedule the events belong to (their `step`; see `_cooldown_point` for files without it).
    """
    path = Path(path)
    events = load_events(path)
    steps = load_schedule(path) if any(e.kind == "cooldown_start" for e in events) else ()
    out, open_, started = [], {}, {}
    for event in events:
        if event.kind == "cooldown_start":
            open_[event.cycle] = (event.time, _cooldown_point(path, steps, event, started))
        elif event.kind == "cooldown_end" and event.cycle in open_:
            t0, point = open_.pop(event.cycle)
            if completed(event, steps):
                out.append((event.cycle, t0, event.time, point))
    return out


def completed(end: Event, steps: Sequence[Step]) -> bool:
    """Whether the cool-down that `end` (a cooldown_end event) closes ran its course: ended by its condition, or on
    time where its step has no condition (a fixed length); not a condition's time-out, not an abort."""
    if end.reason == END_CONDITION:
        return True
    fixed = 0 <= end.step < len(steps) and not steps[end.step].until
    return end.reason == END_TIME and fixed


def _cooldown_point(path: Path, steps: Sequence[Step], start: Event, started: dict[int, int]) -> dict[str, float]:
    """The operating point of the cool-down that `start` (a cooldown_start event) begins: its step's.

    A file written before events carried their step: the n-th cool-down started in a cycle is that cycle's n-th
    step labelled "cooldown" (`started` counts them per cycle).
    """
    if start.step >= 0:
        index = start.step if start.step < len(steps) and steps[start.step].label == COOLDOWN_LABEL else None
        where = f"as step {start.step}"
    else:
        n = started[start.cycle] = started.get(start.cycle, 0) + 1
        ours = [i for i, s in enumerate(steps) if s.cycle == start.cycle and s.label == COOLDOWN_LABEL]
        index = ours[n - 1] if n <= len(ours) else None
        where = f"(the schedule has {len(ours)})"
    if index is None:
        raise InputError(path, "/schedule", f"a step labelled {COOLDOWN_LABEL!r} in cycle {start.cycle} for the "
                                            f"cooldown_start at {start.time:g} s {where}")
    return dict(steps[index].point)


def _noise(values: np.ndarray) -> float:
    """Noise of a held signal from differences between consecutive distinct readings (robust MAD)."""
    v = values[np.isfinite(values)]
    if v.size < 10:
        return math.nan
    change = np.flatnonzero(np.diff(v) != 0)
    d = np.diff(v[np.append(change, change[-1] + 1)]) if change.size > 5 else np.diff(v)
    return robust_sigma(d) / math.sqrt(2.0)


def fit_segment(run: pd.DataFrame, params: Mapping[str, float], t_start: float, t_end: float,
                sample_s: float = 1.0, channels: Sequence[str] = FIT_CHANNELS,
                engine_speed: float | None = None, model: ModelDefinition | None = None) -> dict[str, float]:
    """Fit R and ϑ_P(0) of the 4-state model on [t_start, t_end] of `run` (the /aligned frame).

    The segment starts once no friction power is left from a preceding launch or heat pulse and, if
    `engine_speed` is given, once the engine runs at it (within 2 %). With `model` (a clutch model extended by
    diagnose, say), the segment is fitted with that model's own structure, eq. (11)'s speed terms off (a1 = a2 = 0:
    R = R0 at the segment's fixed operating point), so its points are read as that model reads the sweep.
    """
    dt = float(run.attrs["dt"])
    time = run["time"].to_numpy()
    seg = run[(time >= t_start) & (time <= t_end)].reset_index(drop=True)
    power = seg["friction_power"].to_numpy()
    hot = np.flatnonzero(np.nan_to_num(power) > 0)
    first = hot[-1] + 1 if hot.size and hot[-1] < len(seg) // 4 else 0  # a launch tail at the start
    if engine_speed is not None and engine_speed > 0:
        off = np.flatnonzero(np.abs(seg["engine_speed"].to_numpy()[: len(seg) // 4] - engine_speed) > 0.02 * engine_speed)
        first = max(first, off[-1] + 1 if off.size else 0)
    seg = seg.iloc[first:].reset_index(drop=True)
    seg.attrs.update(run.attrs)
    if len(seg) < 100:
        raise ValueError(f"cool-down [{t_start:g}, {t_end:g}] s too short")
    network = clutch_network("linear") if model is None else build_network(model)
    inputs = input_channels(seg)
    t_seg = seg["time"].to_numpy()
    x0 = initial_state(network, inputs, str(run.attrs.get("source", "<run>")), params=params,
                       seconds=float(t_seg[0] - time[0]))
    names = network.state_names
    # residuals at reading times: the first grid sample of each new reading (a held sample is that
    # reading, late), at most one per `sample_s`
    picks: dict[str, np.ndarray] = {}
    for c in channels:
        v = seg[c].to_numpy()
        new = np.flatnonzero(np.isfinite(v) & np.r_[True, v[1:] != v[:-1]])
        _, first = np.unique(np.floor((t_seg[new] - t_seg[0]) / sample_s), return_index=True)
        picks[c] = new[first]
    measured = {c: seg[c].to_numpy()[picks[c]] for c in channels}
    sigma = {c: _noise(seg[c].to_numpy()) for c in channels}
    sigma = {c: (s if np.isfinite(s) and s > 0 else 0.05) for c, s in sigma.items()}
    out_index = {c: names.index(network.outputs[c]) for c in channels}
    base = dict(params) if model is None else {**params, "a1": 0.0, "a2": 0.0}

    free = ["P"] + [s for s in ("F", "A", "T") if s in names]
    # what the first seconds of readings say about the measured initial states (a prior, not a constraint)
    prior: dict[str, tuple[float, float]] = {}
    for state in free[1:]:
        channel = next(c for c, st in network.outputs.items() if st == state and c in seg)
        # the temperatures the readings stand for (a calibrated sensor's turned back)
        v = temperature_of(network.calibrations.get(channel), base, seg[channel].to_numpy(), t_seg - time[0])
        new = np.flatnonzero(np.isfinite(v) & np.r_[True, v[1:] != v[:-1]])
        new = new[t_seg[new] - t_seg[0] <= INIT_S]
        if new.size >= 3:
            tt, vv = t_seg[new] - t_seg[0], v[new]
            coef = np.polyfit(tt, vv, 1)
            resid = vv - np.polyval(coef, tt)
            noise = max(float(np.std(resid, ddof=2)) if new.size > 3 else 0.0, _noise(v), 1e-3)
            prior[state] = (float(coef[1]), noise * math.sqrt(4.0 / new.size))  # SE of the intercept (approx.)
        if state in prior:
            x0[names.index(state)] = prior[state][0]

    def simulate(theta: np.ndarray) -> np.ndarray:
        p = dict(base)
        p["R0"] = float(theta[0])
        x = x0.copy()
        for name, value in zip(free, theta[1:]):
            x[names.index(name)] = value
        return run_network(network, p, inputs, dt, x)[:-1]

    def read(states: np.ndarray, c: str) -> np.ndarray:
        """Channel c's sensor's readings at its picks (through its calibration, t from the run's first sample)."""
        return reading(network.calibrations.get(c), base, states[picks[c], out_index[c]], t_seg[picks[c]] - time[0])

    def residuals(theta: np.ndarray) -> np.ndarray:
        states = simulate(theta)
        parts = []
        for c in channels:
            parts.append((read(states, c) - measured[c]) / sigma[c])
        for name, value in zip(free[1:], theta[2:]):
            if name in prior:
                parts.append(np.array([(value - prior[name][0]) / prior[name][1]]))
        return np.concatenate(parts)

    r_guess = float(np.clip(params.get("R0", 0.2) + params.get("a1", 0.0) * 0.5, 0.02, 5.0))
    theta0 = np.array([r_guess, x0[names.index("F")] + 2.0] + [x0[names.index(s)] for s in free[1:]])
    k = len(free)
    fit = scipy.optimize.least_squares(residuals, theta0, bounds=([1e-4] + [-50.0] * k, [50.0] + [400.0] * k),
                                       x_scale=np.array([0.05] + [1.0] * k), diff_step=1e-4)
    n, p = fit.fun.size, fit.x.size
    chi2 = float(fit.fun @ fit.fun) / max(1, n - p)
    jac = fit.jac
    cov = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2)
    se = np.sqrt(np.diag(cov))
    states = simulate(fit.x)
    err = np.concatenate([(read(states, c) - measured[c]) for c in channels])
    return {"R": float(fit.x[0]), "R_se": float(se[0]), "T_P0": float(fit.x[1]), "T_P0_se": float(se[1]),
            "rmse_K": float(np.sqrt(np.nanmean(err ** 2))), "n": n, "chi2_red": chi2}


def no_cooldowns(path: "str | os.PathLike[str]") -> InputError:
    """The refusal of a run without completed cool-downs: what the run is instead (its protocol), not a dataset."""
    protocol = load_attrs(path).get("protocol") or "unnamed"
    if protocol != "cooldown-sweep":
        return InputError(path, "protocol", f"a cool-down sweep run (`benchlab run cooldown-sweep`): this is not a "
                                            f"cool-down sweep run ({'an' if protocol[:1] in 'aeiou' else 'a'} {protocol} run), it "
                                            "has no cool-down to fit")
    return InputError(path, "protocol", "a cool-down sweep run with a completed cool-down: this one has none to fit "
                                        "(stopped before its first cool-down ended)")


def segment_model(params: Mapping[str, float]) -> ModelDefinition | None:
    """The structure each cool-down is fitted with: a clutch model extended beyond the built-in ones (diagnose's
    best model, a user's model file) reads the sweep with its own links; the built-in ones with the linear model."""
    definition = getattr(params, "definition", None)
    return definition if definition is not None and definition.alias is None else None


def analyse(path: "str | os.PathLike[str]", params: Mapping[str, float], sample_s: float = 1.0,
            progress: Progress = SILENT, model: ModelDefinition | None = None,
            run: pd.DataFrame | None = None) -> list[CooldownResult]:
    """Every cool-down of a cooldown-sweep run, fitted (one progress step each; with `model`'s structure where given:
    fit_segment); R_true filled in for a simulated bench. `run`: the caller's `load_run(path)`, not read again (a
    2 h sweep's channels take 0.5 s to read). A run without completed cool-downs (or without /events at all: another
    tool's file) is no_cooldowns' InputError."""
    path = Path(path)
    run = load_run(path) if run is None else run
    sim_truth = load_attrs(path).get("sim_truth")
    recorded = json.loads(sim_truth) if sim_truth is not None else {}
    # the true R of eq. (11) exists only for the paper's plant (the reference clutch has no such resistance)
    truth = recorded.get("params") if recorded.get("plant", "paper") == "paper" else None
    try:
        found = segments(path)
    except InputError as exc:
        if exc.field != "/events":
            raise
        found = []
    if not found:
        raise no_cooldowns(path)
    with progress.task("cool-downs", len(found), unit="fit") as task:
        return [_fit_cooldown(run, params, sample_s, truth, model, *segment, task) for segment in found]


def _fit_cooldown(run: pd.DataFrame, params: Mapping[str, float], sample_s: float, truth: Mapping[str, float] | None,
                  model: ModelDefinition | None,
                  cycle: int, t0: float, t1: float, point: Mapping[str, float], task: Task) -> CooldownResult:
    """One cool-down's fit, with the plant's true resistance at its operating point where known."""
    rpm, state = point.get("engine_speed", math.nan), int(point.get("clutch_state", 0))
    fit = fit_segment(run, params, t0, t1, sample_s, engine_speed=rpm if math.isfinite(rpm) else None, model=model)
    r_true = math.nan
    if truth is not None:
        r_true = float(np.asarray(convection_resistance(truth, {"engine_speed": np.array([rpm]),
                                                                 "clutch_state": np.array([float(state)])})).ravel()[0])
    task.advance()
    return CooldownResult(cycle, rpm, state, point.get("slip_speed", math.nan), t0, t1, fit["R"], fit["R_se"],
                          COVERAGE_K * math.hypot(fit["R_se"], SYSTEMATIC_REL * fit["R"]), fit["T_P0"],
                          fit["T_P0_se"], fit["rmse_K"], int(fit["n"]), fit["chi2_red"], r_true)


#: eq. (11)'s parameters of each clutch state's branch (S = 1 clamped, S = 0 open); R0 is shared
BRANCHES = {1: ("a1", "b1"), 0: ("a2", "b2")}


def fit_eq11(results: Sequence[CooldownResult], partial: bool = False,
             held: Mapping[str, float] | None = None) -> dict[str, float]:
    """a1, b1, a2, b2, R0 (and *_se) of eq. (11) from the per-point resistances; ValueError if underdetermined.

    `partial`: the branches the points determine (at least 2 engine speeds in that clutch state) with R0, the
    others left out (a designed run's cool-downs may all be in one clutch state: docs/design.md). `held`: values
    (b in 1/rpm) kept as given instead of fitted (returned without a standard error). `chi2_red` is the points'
    reduced chi-square against their own errors; `scatter` the between-reading share of R that brings it to 1 (0
    where it is at most 1; absent where the points leave no degree of freedom to tell)."""
    held = dict(held or {})
    rows = [r for r in results if np.isfinite(r.R) and r.R_se > 0]
    speeds = {s: {r.engine_speed for r in rows if r.clutch_state == s} for s in BRANCHES}
    states = [s for s in BRANCHES if len(speeds[s]) >= 2] if partial else list(BRANCHES)
    rows = [r for r in rows if r.clutch_state in states]
    names = tuple(n for s in states for n in BRANCHES[s] if n not in held) + ("R0",)
    if not states or any(len(speeds[s]) < 2 for s in states) or len(rows) < len(names) or \
            len({(r.engine_speed, r.clutch_state) for r in rows}) < len(names) - len(states) + 1 - len(held):
        raise ValueError("eq. (11) needs at least 5 cool-downs with 2 engine speeds in each clutch state"
                         + (" (or 3 engine speeds in one of them)" if partial else ""))
    y = np.array([r.R for r in rows])
    se = np.array([r.R_se for r in rows])
    operating_point = {"engine_speed": np.array([r.engine_speed for r in rows]) / 1000.0,  # krpm, for conditioning
                       "clutch_state": np.array([float(r.clutch_state) for r in rows])}
    fit = _weighted_eq11(y, se, operating_point, names, held)
    n, p = y.size, len(names)
    chi2 = float(fit.fun @ fit.fun) / (n - p) if n > p else math.nan
    scatter = between_reading_scatter(y, se, operating_point, names, held) if n > p and chi2 > 1 else 0.0
    if scatter > 0:
        fit = _weighted_eq11(y, np.hypot(se, scatter * y), operating_point, names, held)
    errors = np.sqrt(np.diag(np.linalg.pinv(fit.jac.T @ fit.jac)))
    scale = np.array([1e-3 if name.startswith("b") else 1.0 for name in names])  # b in 1/rpm
    out = {k: float(v * c) for k, v, c in zip(names, fit.x, scale)}
    out.update({f"{k}_se": float(v * c) for k, v, c in zip(names, errors, scale)})
    out.update({k: float(v) for k, v in held.items() if k in {m for s in states for m in BRANCHES[s]}})
    out["chi2_red"] = chi2
    if n > p:
        out["scatter"] = scatter
    out["points"] = n
    return out


def _weighted_eq11(y: np.ndarray, se: np.ndarray, operating_point: Mapping[str, np.ndarray], names: Sequence[str],
                   held: Mapping[str, float]) -> scipy.optimize.OptimizeResult:
    """eq. (11)'s `names` fitted to the points R = y by least squares with weights 1/se² (b in 1/krpm here)."""
    kept = {n: v * 1e3 if n.startswith("b") else v for n, v in held.items()}

    def model(th: np.ndarray) -> np.ndarray:
        return convection_resistance({"a1": 0.0, "b1": 0.0, "a2": 0.0, "b2": 0.0, **kept, **dict(zip(names, th))},
                                     operating_point)

    start = {"a1": 0.3, "b1": -1.0, "a2": 0.4, "b2": -1.0, "R0": max(1e-3, 0.8 * y.min())}
    lower = {"a1": 0.0, "b1": -20.0, "a2": 0.0, "b2": -20.0, "R0": 0.0}
    upper = {"a1": 50.0, "b1": 5.0, "a2": 50.0, "b2": 5.0, "R0": 50.0}
    return scipy.optimize.least_squares(lambda th: (model(th) - y) / se, np.array([start[n] for n in names]),
                                        bounds=([lower[n] for n in names], [upper[n] for n in names]))


def between_reading_scatter(y: np.ndarray, se: np.ndarray, operating_point: Mapping[str, np.ndarray],
                            names: Sequence[str], held: Mapping[str, float]) -> float:
    """The Paule–Mandel share s of R: each point's variance se² + (s·R)², s where eq. (11)'s reduced chi-square is
    1 (the fit has more points than `names`, and its chi-square at s = 0 is above 1)."""
    dof = y.size - len(names)

    def excess(share: float) -> float:
        errors = np.hypot(se, share * y)
        fit = _weighted_eq11(y, errors, operating_point, names, held)
        return float(fit.fun @ fit.fun) / dof - 1.0

    high = 0.01
    while (above := excess(high) > 0) and high < 100.0:
        high *= 2.0
    return high if above else float(scipy.optimize.brentq(excess, 0.0, high, xtol=1e-4))


def store(path: "str | os.PathLike[str]", results: Sequence[CooldownResult], eq11: Mapping[str, float] | None,
          params_source: str = "", out: "str | os.PathLike[str] | None" = None) -> None:
    """Write /analysis/cooldowns (one dataset per column, with units) and /analysis/eq11 into the file `out` of its
    own (the run file `path` untouched), or into the run file where `out` is None (asked for explicitly)."""
    rows = [asdict(r) for r in results]
    attrs = {"coverage_k": COVERAGE_K, "params": params_source, "method": METHOD}
    if out is None:
        write_analysis(path, rows, eq11, attrs)
    else:
        write_analysis_file(out, path, rows, eq11, attrs)


@dataclass(frozen=True)
class StoredCooldowns:
    """The cool-downs `store` wrote into a run file, with the parameter file they were fitted with."""

    results: list[CooldownResult]
    eq11: dict[str, float] | None
    params_source: str


def stored(path: "str | os.PathLike[str]") -> StoredCooldowns | None:
    """The run file's /analysis as `store` wrote it; None when the run has none (not analysed yet)."""
    analysis = load_analysis(path)
    if analysis is None:
        return None
    integers = {"cycle", "clutch_state", "n"}
    results = [CooldownResult(**{f.name: int(row[f.name]) if f.name in integers else row[f.name]
                                 for f in fields(CooldownResult)}) for row in analysis.cooldowns]
    return StoredCooldowns(results, analysis.eq11, analysis.attrs.get("params", ""))


def table_lines(results: Sequence[CooldownResult], eq11: Mapping[str, float] | None) -> list[str]:
    lines = ["cycle  engine_rpm  S  slip_rpm     R K/W    ±U(k=2)    T_P0 degC   rmse K   R_true"]
    for r in results:
        lines.append(f"{r.cycle:5d}  {r.engine_speed:10.0f}  {r.clutch_state:d}  {r.slip_speed:8.0f}  {r.R:8.4f}  "
                     f"{r.R_u:9.4f}  {r.T_P0:10.2f}  {r.rmse_K:7.3f}  {r.R_true:7.4f}")
    if eq11 is not None:
        lines.append("eq. (11): " + ", ".join(f"{k} = {eq11[k]:.4g} ± {eq11[k + '_se']:.2g}"
                                              for k in ("a1", "b1", "a2", "b2", "R0") if k in eq11))
    return lines
