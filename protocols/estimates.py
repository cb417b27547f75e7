"""Expected durations of the closed-loop steps a plan cannot time exactly: pulsed heat-ups and cool-downs.

From the paper's parameters (the plant a simulated bench runs; a hardware bench's clutch is of the same size), for
`benchlab run --dry-run`'s estimate and a run's progress. A step still ends on its condition; these only say when
that is expected. Measured against the simulated bench in tests/test_plans.py (within 10 % per protocol).
"""

from __future__ import annotations

import math

from benchlab.drivetrain import RPM

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
