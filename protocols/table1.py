"""Table 1 identification protocol: random launches and cool-downs, seeded and reproducible.

Each load cycle draws engine speed, clutch torque, load torque and cool-down time from the
paper's Table 1. A cycle is a vehicle launch (torque-controlled engagement until synchronous,
at most `max_slip_s`), then the cool-down: the first half driving with the clutch clamped, the
second half stopped with the clutch open, the engine held at the cycle's speed throughout, so
both clutch states are seen at every engine speed.
"""

from __future__ import annotations

import numpy as np

from protocols.schedule import Step

ENGINE_SPEEDS_RPM = (1000.0, 1500.0, 2000.0)
CLUTCH_TORQUES_NM = (30.0, 45.0, 65.0)
LOAD_TORQUES_NM = (100.0, 300.0, 500.0)
COOLDOWN_S = (30.0, 50.0, 60.0, 80.0, 90.0, 120.0)
MAX_SLIP_S = 10.0


def table1_schedule(seed: int, n_cycles: int | None = None, duration_s: float | None = None,
                    max_slip_s: float = MAX_SLIP_S) -> tuple[Step, ...]:
    """Draw cycles until `n_cycles` or the planned `duration_s` is reached (one of them is required)."""
    if (n_cycles is None) == (duration_s is None):
        raise ValueError("give exactly one of n_cycles or duration_s")
    rng = np.random.default_rng(seed)
    steps: list[Step] = []
    planned, cycle = 0.0, 0
    while (n_cycles is not None and cycle < n_cycles) or (duration_s is not None and planned < duration_s):
        speed = float(rng.choice(ENGINE_SPEEDS_RPM))
        torque = float(rng.choice(CLUTCH_TORQUES_NM))
        load = float(rng.choice(LOAD_TORQUES_NM))
        cooldown = float(rng.choice(COOLDOWN_S))
        steps += [
            Step("launch", max_slip_s, speed, torque, load, cycle),
            Step("drive", cooldown / 2, speed, torque, load, cycle),
            Step("open", cooldown / 2, speed, 0.0, load, cycle),
        ]
        planned += max_slip_s + cooldown
        cycle += 1
    return tuple(steps)
