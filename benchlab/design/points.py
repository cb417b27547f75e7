"""Precision of eq. (11) read from the designed run's cool-downs: one conductance point per cool-down, then eq. (11)
fitted to the points (the paper's procedure, its Fig. 3: `benchlab.identify.cooldown`, `benchlab.identify.staged`).

Where the model lacks structure the plant has, a joint fit of the designed run with the runs so far bends other
parameters instead of eq. (11) (docs/design.md); each cool-down read on its own, the other parameters held at the
runs' values, gives R at its operating point whatever the rest of the model does wrong, and eq. (11) follows from
those points. The design predicts what that reading will give:

* each candidate block's cool-down as the model predicts it (`fisher.predicted_run`), white noise at the runs'
  channel noise added, read by the reading itself (`cooldown.fit_segment`): the relative standard error of R there;
* scaled by the misfit the reading will meet: the segment fit scales its error by the square root of its reduced
  chi-square, which on the bench is the model's misfit against the noise; expected from the runs so far (the
  parameter file's RMSE per channel against the channel's noise), printed;
* the points' information on ln|θ| of eq. (11): g gᵀ / SE² per point, g = dR/d ln|θ| at the point; the parameters
  designed for with the rest of eq. (11) as nuisance (`fisher.schur`), greedy per second of bench time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchlab.design import fisher
from benchlab.design.blocks import Block
from benchlab.errors import InputError
from benchlab.identify.cooldown import BRANCHES, FIT_CHANNELS, CooldownResult, fit_eq11, fit_segment
from benchlab.identify.staged import EQ11
from benchlab.model.clutch import convection_resistance
from benchlab.model.definition import ModelDefinition
from benchlab.network import ThermalNetwork
from benchlab.runfile import load_events, load_run, load_schedule
from benchlab.runfile.schema import END_TIME
from protocols.limits import BenchLimits

#: Seed of the white noise added to the predicted cool-downs (the expected error should not change from call to call).
NOISE_SEED = 0


def operating_point(block: Block) -> dict[str, float]:
    """The block's cool-down operating point (its last step's, as the reading takes it from the schedule)."""
    return dict(block.steps[-1].point)


def misfit_factor(fitting: Mapping[str, object], noise: Mapping[str, float]) -> float:
    """sqrt of the reduced chi-square the cool-down reading is expected to meet: the model's RMSE per channel on
    the runs so far (the parameter file's `fit.fitting`) against the channel's noise, over the reading's channels;
    1 where the file holds no RMSE."""
    ratios = []
    for channel in FIT_CHANNELS:
        rmse = [float(run["channels"][channel]["rmse_K"]) for run in fitting.values()
                if isinstance(run, dict) and channel in run.get("channels", {})]
        if rmse and noise.get(channel, 0.0) > 0:
            ratios.append(np.mean(np.square(rmse)) / noise[channel] ** 2)
    return float(np.sqrt(max(1.0, np.mean(ratios)))) if ratios else 1.0


def point_error(block: Block, params: Mapping[str, float], network: ThermalNetwork, ambient_c: float,
                limits: BenchLimits, noise: Mapping[str, float], model: ModelDefinition | None = None) -> float:
    """Relative standard error of R the reading gives for the block's cool-down (with `model`'s structure where
    given: `cooldown.fit_segment`), on the run as the model predicts it with white noise at `noise` (the reading's
    own chi-square about 1 here: no misfit)."""
    steps = fisher.open_loop(block.steps, params, network, ambient_c)  # a cool-down to a temperature: its length
    frame = fisher.predicted_run(steps, params, network, ambient_c, limits.drivetrain)
    rng = np.random.default_rng(NOISE_SEED)
    for channel in FIT_CHANNELS:
        if channel in frame and channel in noise:
            frame[channel] = frame[channel].to_numpy() + rng.normal(0.0, noise[channel], len(frame))
    end = float(frame["time"].iloc[-1])
    point = operating_point(block)
    fit = fit_segment(frame, params, end - steps[-1].duration_s, end, engine_speed=point["engine_speed"],
                      model=model)
    return fit["R_se"] / fit["R"]


def sensitivity(params: Mapping[str, float], point: Mapping[str, float]) -> np.ndarray:
    """dR / d ln|θ| for θ in EQ11 at the operating point (forward differences, as `fisher.jacobian`)."""
    channels = {k: np.array([point[k]]) for k in ("engine_speed", "clutch_state")}
    base = float(np.ravel(convection_resistance(params, channels))[0])
    moved = [{**params, n: params[n] * (1.0 + fisher.RELATIVE_STEP)} for n in EQ11]
    return np.array([(float(np.ravel(convection_resistance(p, channels))[0]) - base) / np.log1p(fisher.RELATIVE_STEP)
                     for p in moved])


def point_information(block: Block, params: Mapping[str, float], relative_error: float) -> np.ndarray:
    """The information one cool-down point gives on ln|θ| of EQ11: g gᵀ / SE², SE = relative_error · R."""
    point = operating_point(block)
    channels = {k: np.array([point[k]]) for k in ("engine_speed", "clutch_state")}
    resistance = float(np.ravel(convection_resistance(params, channels))[0])
    g = sensitivity(params, point)
    return np.outer(g, g) / (relative_error * resistance) ** 2


#: The shortest held stretch of a run so far read as a point for the design's values (s): shorter ones hardly cool.
SHORTEST_HELD_S = 30.0


def held_stretches(path: Path) -> list[tuple[float, float, dict[str, float]]]:
    """(t_start, t_end, operating point) of every stretch of the run held at one engine speed without slip heat:
    its steps that drive clamped or stand open for their whole time (a Table 1 cycle's two cool-down halves), at
    least SHORTEST_HELD_S long; none for a run without its schedule (another tool's file)."""
    try:
        steps = load_schedule(path)
    except InputError:
        return []
    started: dict[int, float] = {}
    out = []
    for event in load_events(path):
        if event.kind == "step_start" and 0 <= event.step < len(steps):
            started[event.step] = event.time
        elif event.kind == "step_end" and event.step in started and event.reason == END_TIME:
            step, t0 = steps[event.step], started.pop(event.step)
            held = step.phase in ("drive", "open") and not step.until and event.time - t0 >= SHORTEST_HELD_S
            if held:
                state = 1.0 if step.phase == "drive" else 0.0
                out.append((t0, event.time, {"engine_speed": step.engine_speed_rpm, "clutch_state": state}))
    return out


def held_points(paths: Sequence[Path], params: Mapping[str, float],
                model: ModelDefinition | None = None) -> list[CooldownResult]:
    """Each held stretch of the runs (`held_stretches`) read as a cool-down (`cooldown.fit_segment`, with
    `model`'s structure where given): R at its operating point with its standard error."""
    found = []
    for path in paths:
        run = load_run(path)
        for t0, t1, point in held_stretches(Path(path)):
            try:
                fit = fit_segment(run, params, t0, t1, engine_speed=point["engine_speed"], model=model)
            except ValueError:  # too short once the launch's heat and the engine's settling are cut
                continue
            found.append(CooldownResult(-1, point["engine_speed"], int(point["clutch_state"]), math.nan, t0, t1,
                                        fit["R"], fit["R_se"], math.nan, fit["T_P0"], fit["T_P0_se"], fit["rmse_K"],
                                        int(fit["n"]), fit["chi2_red"], math.nan))
    return found


@dataclass(frozen=True)
class RunsReading:
    """What the runs so far, read as the designed run will be, say: eq. (11)'s values to design with, how far
    their points disagree with eq. (11) beyond their own errors (sqrt of the fit's reduced chi-square, at least 1),
    and the between-reading scatter on the branches designed for (`cooldown.fit_eq11`'s share of R: the same
    operating point read at different times of the runs' history)."""

    values: dict[str, float]
    disagreement: float
    scatter: float


def read_runs(paths: Sequence[Path], params: Mapping[str, float], start: Mapping[str, float],
              bounds: Mapping[str, tuple[float, float]], interest: Sequence[str],
              model: ModelDefinition | None = None) -> RunsReading:
    """The runs so far read the way the designed run will be: each held stretch a point (`held_points`). The
    disagreement from eq. (11) fitted to the points of the branches they determine (`cooldown.fit_eq11`, partial),
    the scatter from the points of the branches `interest` lies in alone, read from the longer half of their
    stretches (`longer_half`); the values from the amplitudes and R0
    fitted with the curvatures b at `start` (the model file's: Table 1's 1000-2000 rpm hardly show them), `start`
    for what the points leave out or put on or beyond `bounds`. Without points to tell (another tool's runs), no
    disagreement and no scatter."""
    found = held_points(paths, params, model)
    try:
        chi2 = fit_eq11(found, partial=True)["chi2_red"]
        eq11 = fit_eq11(found, partial=True, held={n: start[n] for n in ("b1", "b2")})
        scatter = fit_eq11(longer_half([p for p in found if p.clutch_state in branch_states(interest)]),
                           partial=True)
    except ValueError:
        return RunsReading({n: start[n] for n in EQ11}, 1.0, 0.0)
    values = {n: eq11[n] if n in eq11 and bounds[n][0] < eq11[n] < bounds[n][1] else start[n] for n in EQ11}
    return RunsReading(values, float(np.sqrt(max(1.0, chi2))) if np.isfinite(chi2) else 1.0,
                       float(scatter.get("scatter", 0.0)))


def longer_half(found: Sequence[CooldownResult]) -> list[CooldownResult]:
    """The points read from the longer half of their stretches (at least the median length): the readings most like
    a designed cool-down, which is longer still. A held stretch's reading carries more of the run's history the
    shorter it is (Table 1's 45-60 s stretches scatter 5-16 % of R, its 30-40 s ones 15-37 %, seeds 101-104)."""
    lengths = np.array([p.t_end - p.t_start for p in found])
    return [p for p, length in zip(found, lengths) if length >= np.median(lengths)] if found else []


def branch_states(interest: Sequence[str]) -> set[int]:
    """The clutch states whose branch of eq. (11) `interest` lies in (both where it names only R0)."""
    return {state for state, pair in BRANCHES.items() if set(pair) & set(interest)} or {0, 1}


def determines(blocks: Sequence[Block], interest: Sequence[str]) -> bool:
    """Whether the blocks' cool-down points determine the branches of eq. (11) that `interest` lies in and show
    their scatter: at least three engine speeds in each such clutch state (its a, b and R0), and a point more than
    those branches have parameters (a degree of freedom for `cooldown.fit_eq11` to estimate the between-reading
    scatter from, without which its errors are the points' alone)."""
    needed = branch_states(interest)
    own = [operating_point(b) for b in blocks if operating_point(b)["clutch_state"] in needed]
    return (all(len({p["engine_speed"] for p in own if p["clutch_state"] == state}) >= 3 for state in needed)
            and len(own) > 2 * len(needed) + 1)  # a and b per branch, and R0
