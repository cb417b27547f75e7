"""Expected durations of the closed-loop steps a plan cannot time exactly: pulsed heat-ups and cool-downs.

From the paper's parameters (the plant a simulated bench runs; a hardware bench's clutch is of the same size), for
`benchlab run --dry-run`'s estimate and a run's progress. A step still ends on its condition; these only say when
that is expected. Measured against the simulated bench in tests/test_plans.py (within 10 % per protocol).

A cool-down sweep's heat-ups and cool-downs are, where the plant the run will use is known (the simulated bench's,
or a parameter file's), simulated on that plant (`timed`, `played`: the closed-loop steps played on it with the
runner's rules): the paper's closed forms above missed the reference plant's sweep by almost half (4304 s against
7881 s of bench time). A designed run's closed-loop steps are predicted the same way (benchlab.design.fisher).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, Protocol

from benchlab.drivetrain import RPM
from protocols.schedule import Condition, Step, pulse_due

#: Where a run starts: the bench at room temperature.
ROOM_C = 22.0
#: What a hot flywheel cools towards within a cool-down (the chamber air and the housing warm up with it).
COOL_SINK_C = 40.0


def heat_estimate_s(start_c: float, target_c: float, speed_rpm: float, torque_nm: float, pulse_s: float,
                    rest_s: float, steady_window_s: float = 0.0) -> float:
    """Time for pulsed slip (`torque_nm` at `speed_rpm`, `pulse_s` on, `rest_s` off) to bring plate and flywheel
    from `start_c` to `target_c`, plus the window a "steady" condition must then hold."""
    from benchlab.model.params import paper_params

    p = paper_params("nonlinear")
    mean_power_w = torque_nm * speed_rpm * RPM * pulse_s / (pulse_s + rest_s)
    return steady_window_s + max(0.0, target_c - start_c) * (p["C_P"] + p["C_F"]) / mean_power_w


def cooling_time_constant_s(rpm: float, state: int) -> float:
    """The flywheel's cooling time constant C_F · R_FA(ω_e, S) (eq. 11) at an operating point."""
    import numpy as np

    from benchlab.model.clutch import convection_resistance
    from benchlab.model.params import paper_params

    p = paper_params("nonlinear")
    r = float(convection_resistance(p, {"engine_speed": np.array([rpm]), "clutch_state": np.array([state])})[0])
    return p["C_F"] * r


def cool_estimate_s(rpm: float, state: int, from_c: float, to_c: float) -> float:
    """Time for the flywheel to cool from `from_c` to `to_c` at (ω_e, S), towards COOL_SINK_C."""
    ratio = (from_c - COOL_SINK_C) / max(to_c - COOL_SINK_C, 1e-9)
    return cooling_time_constant_s(rpm, state) * math.log(max(ratio, 1.0))


def cooled_to(from_c: float, rpm: float, state: int, seconds: float) -> float:
    """The flywheel's temperature after `seconds` of cooling from `from_c` at (ω_e, S)."""
    if from_c <= COOL_SINK_C:
        return from_c
    return COOL_SINK_C + (from_c - COOL_SINK_C) * math.exp(-seconds / cooling_time_constant_s(rpm, state))


class Plant(Protocol):
    """What a sweep's estimate needs of a thermal plant (sim_bench.plant.ThermalPlant): its state, advanced by the
    drivetrain's channels, and what its flywheel sensors read."""

    state: Any
    state_names: list[str]

    def reset(self, temperature_c: float | Mapping[str, float]) -> None: ...
    def advance(self, channels: Mapping[str, Any], dt: float) -> dict[str, Any]: ...
    def sensor_temperatures(self, true_states: Mapping[str, Any]) -> dict[str, Any]: ...
    def friction_factor(self) -> float: ...


#: The step of a sweep's simulated estimate (s) and the length of one cool-down piece simulated at once (s).
ESTIMATE_DT_S = 0.5
COOL_PIECE_S = 60.0


#: The channels a sweep's estimate feeds its plant (what `_flywheel` sets): a model whose laws read others cannot
#: time the sweep.
ESTIMATE_CHANNELS = ("engine_speed", "clutch_speed", "clutch_torque", "clutch_state", "friction_power",
                     "load_torque", "T_ambient")


def _flywheel(plant: Plant, seconds: float, rpm: float, shaft_rpm: float, state: int, torque_nm: float,
              dt: float, ambient_c: float = ROOM_C) -> Any:
    """The flywheel sensors' mean over `seconds` at one operating point (friction power where the clutch slips
    under `torque_nm`, as much as the lining's μ(ϑ) transmits); the plant's state moves to the end."""
    import numpy as np

    n = max(1, int(round(seconds / dt)))
    power = torque_nm * plant.friction_factor() * (rpm - shaft_rpm) * RPM
    channels = dict(zip(ESTIMATE_CHANNELS, (rpm, shaft_rpm, torque_nm, float(state), power, 0.0, ambient_c)))
    seen = plant.sensor_temperatures(plant.advance({k: np.full(n, v) for k, v in channels.items()}, dt))
    return 0.5 * (seen["T_flywheel_1"] + seen["T_flywheel_2"])


def _holds(conditions: Sequence[Condition], history: list[float], dt: float) -> bool:
    """Whether any of `conditions` on the flywheel holds on its readings `history` (every `dt`), by the runner's
    tests (a threshold on the last reading, `Condition.steady_over`)."""
    import numpy as np

    now = history[-1]
    for c in conditions:
        if c.channel != "T_flywheel":
            continue
        if (c.op == ">=" and now >= c.value) or (c.op == "<=" and now <= c.value):
            return True
        if c.op == "steady":
            times = np.arange(len(history)) * dt
            if c.steady_over(times, np.asarray(history), times[-1]):
                return True
    return False


def _heat_pulses(plant: Plant, step: Step, dt: float, ambient_c: float) -> tuple[Step, ...]:
    """A "heat" step played on `plant` as the runner plays it (protocols.schedule `pulse_due` against its first
    condition's value; 2 s for the shaft to come to rest under the load, then per period a pulse where due and a
    rest) until its conditions hold or it times out: the open-loop steps it becomes, each pulse a launch against the
    holding load (the set-points a pulse gives), each rest an open clutch."""
    hold = (step.engine_speed_rpm, 0.0)
    target = step.until[0].value if step.until else math.inf
    rest = replace(step, phase="open", duration_s=step.rest_s, clutch_torque_nm=0.0, until=(), estimate_s=None)
    pulse = replace(step, phase="launch", duration_s=step.pulse_s, until=(), estimate_s=None)
    out = [replace(rest, duration_s=2.0)]
    history = list(_flywheel(plant, 2.0, *hold, 0, 0.0, dt, ambient_c))
    rise = 0.0
    while not _holds(step.until, history, dt) and len(history) * dt < step.duration_s:
        before = history[-1]
        if pulse_due(before, target, rise):
            heated = _flywheel(plant, step.pulse_s, *hold, 1, step.clutch_torque_nm, dt, ambient_c)
            history += list(heated)
            rise = max(0.0, float(heated[-1]) - before)
            out.append(pulse)
        history += list(_flywheel(plant, step.rest_s, *hold, 0, 0.0, dt, ambient_c))
        out.append(rest)
    return tuple(out)


def _until_met(plant: Plant, step: Step, rpm: float, shaft_rpm: float, state: int, dt: float,
               ambient_c: float) -> float:
    """Seconds a step that holds its operating point until a threshold on the flywheel (a cool-down to a
    temperature) lasts on `plant`, at most its time-out; the plant's state moves to where the step ends."""
    import numpy as np

    spent = 0.0
    while spent < step.duration_s:
        start = plant.state.copy()
        piece = _flywheel(plant, COOL_PIECE_S, rpm, shaft_rpm, state, 0.0, dt, ambient_c)
        met = np.flatnonzero([_holds(step.until, [value], dt) for value in piece])
        if len(met):  # ends inside this piece: the plant goes back to where the step would end
            plant.reset(dict(zip(plant.state_names, start)))
            _flywheel(plant, (met[0] + 1) * dt, rpm, shaft_rpm, state, 0.0, dt, ambient_c)
            return min(spent + (met[0] + 1) * dt, step.duration_s)
        spent += COOL_PIECE_S
    return step.duration_s


def played(steps: Sequence[Step], plant: Plant, dt: float = ESTIMATE_DT_S,
           ambient_c: float = ROOM_C) -> list[tuple[Step, ...]]:
    """Each step as it is expected to go on `plant` from its present state, open loop: a "heat" step its pulses and
    rests (`_heat_pulses`), a step that ends on a condition that step at the length it lasts, every other step as
    it is. The one model of the closed-loop steps a plan holds: their expected durations (`timed`) and a designed
    run's prediction (benchlab.design.fisher `predicted_run`)."""
    out: list[tuple[Step, ...]] = []
    shaft = 0.0
    for step in steps:
        rpm = step.engine_speed_rpm
        if step.phase == "heat":
            out.append(_heat_pulses(plant, step, dt, ambient_c))
            shaft = 0.0
            continue
        if step.phase in ("launch", "drive") and step.load_torque_nm == 0.0:
            shaft, state, torque = rpm, 1, 0.0  # synchronises at once: no slip heat worth timing
        elif step.phase == "launch":
            shaft, state, torque = 0.0, 1, step.clutch_torque_nm  # slips against the load
        else:
            shaft, state, torque = (0.0 if step.load_torque_nm > 0 else shaft), 0, 0.0
        if step.until:
            seconds = _until_met(plant, step, rpm, shaft, state, dt, ambient_c)
            out.append((replace(step, duration_s=seconds, until=(), estimate_s=None),))
        else:
            _flywheel(plant, step.expected_s, rpm, shaft, state, torque, dt, ambient_c)
            out.append((step,))
    return out


def timed(steps: Sequence[Step], plant: Plant) -> tuple[Step, ...]:
    """`steps` with each closed-loop step's expected duration as it goes on `plant` from ROOM_C (`played`)."""
    plant.reset(ROOM_C)
    return tuple(replace(step, estimate_s=round(min(sum(s.duration_s for s in went), step.duration_s), 1))
                 if step.phase == "heat" or step.until else step for step, went in zip(steps, played(steps, plant)))
