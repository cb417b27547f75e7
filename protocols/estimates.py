"""Expected durations of the closed-loop steps a plan cannot time exactly: pulsed heat-ups and cool-downs.

From the paper's parameters (the plant a simulated bench runs; a hardware bench's clutch is of the same size), for
`benchlab run --dry-run`'s estimate and a run's progress. A step still ends on its condition; these only say when
that is expected. Measured against the simulated bench in tests/test_plans.py (within 10 % per protocol).

A cool-down sweep's heat-ups and cool-downs are, where the plant the run will use is known (the simulated bench's,
or a parameter file's), simulated on that plant (`sweep_durations`): the paper's closed forms above missed the
reference plant's sweep by almost half (4304 s against 7881 s of bench time).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from benchlab.drivetrain import RPM
from protocols.schedule import Condition, pulse_due

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
              dt: float) -> Any:
    """The flywheel sensors' mean over `seconds` at one operating point (friction power where the clutch slips
    under `torque_nm`, as much as the lining's μ(ϑ) transmits); the plant's state moves to the end."""
    import numpy as np

    n = max(1, int(round(seconds / dt)))
    power = torque_nm * plant.friction_factor() * (rpm - shaft_rpm) * RPM
    channels = dict(zip(ESTIMATE_CHANNELS, (rpm, shaft_rpm, torque_nm, float(state), power, 0.0, ROOM_C)))
    seen = plant.sensor_temperatures(plant.advance({k: np.full(n, v) for k, v in channels.items()}, dt))
    return 0.5 * (seen["T_flywheel_1"] + seen["T_flywheel_2"])


def sweep_durations(points: Sequence[tuple[float, int, float]], heat: Mapping[str, float], plant: Plant,
                    dt: float = ESTIMATE_DT_S) -> list[tuple[float, float]]:
    """(heat-up, cool-down) seconds of each sweep point, simulated on `plant` from ROOM_C in the order the run
    goes: pulses at `heat`'s torque and speed with the heat step's pulse rule (protocols.schedule `pulse_due`) until
    the flywheel is steady at the target (the runner's test, `Condition.steady_over`), then (ω_e, S, shaft speed)
    until it reads the cool-down target. `heat`: the
    SweepConfig's fields; `points`: (engine rpm, S, shaft rpm)."""
    import numpy as np

    plant.reset(ROOM_C)
    out = []
    hold = (heat["heat_speed_rpm"], 0.0)
    steady = Condition("T_flywheel", "steady", heat["heat_target_c"], heat["band_k"], heat["window_s"], heat["drift_k"])

    def settled(history: list[float]) -> bool:
        times = np.arange(len(history)) * dt
        return steady.steady_over(times, np.asarray(history), times[-1])

    for rpm, state, shaft in points:
        history = list(_flywheel(plant, 2.0, *hold, 0, 0.0, dt))  # the shaft comes to rest under the load first
        rise = 0.0
        while not settled(history) and len(history) * dt < heat["heat_timeout_s"]:
            before = history[-1]
            if pulse_due(before, heat["heat_target_c"], rise):
                pulse = _flywheel(plant, heat["pulse_s"], *hold, 1, heat["heat_torque_nm"], dt)
                history += list(pulse)
                rise = max(0.0, float(pulse[-1]) - before)
            history += list(_flywheel(plant, heat["rest_s"], *hold, 0, 0.0, dt))
        cooled = 0.0
        while cooled < heat["cool_timeout_s"]:
            start = plant.state.copy()
            piece = _flywheel(plant, COOL_PIECE_S, rpm, shaft, state, 0.0, dt)
            below = np.flatnonzero(piece <= heat["cool_target_c"])
            if len(below):  # ends inside this piece: the plant goes back to where the step would end
                plant.reset(dict(zip(plant.state_names, start)))
                _flywheel(plant, (below[0] + 1) * dt, rpm, shaft, state, 0.0, dt)
                cooled += (below[0] + 1) * dt
                break
            cooled += COOL_PIECE_S
        out.append((len(history) * dt, min(cooled, heat["cool_timeout_s"])))
    return out
