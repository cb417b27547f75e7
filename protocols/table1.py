"""Table 1 identification protocol: random launches and cool-downs, seeded and reproducible.

Each load cycle draws engine speed, clutch torque, load torque and cool-down time from the
paper's Table 1. A cycle is a vehicle launch (torque-controlled engagement until synchronous,
at most `max_slip_s`), then the cool-down: the first half driving with the clutch clamped, the
second half stopped with the clutch open, the engine held at the cycle's speed throughout, so
both clutch states are seen at every engine speed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from protocols.schedule import Step

if TYPE_CHECKING:
    from protocols.limits import BenchLimits

ENGINE_SPEEDS_RPM = (1000.0, 1500.0, 2000.0)
CLUTCH_TORQUES_NM = (30.0, 45.0, 65.0)
LOAD_TORQUES_NM = (100.0, 300.0, 500.0)
COOLDOWN_S = (30.0, 50.0, 60.0, 80.0, 90.0, 120.0)
MAX_SLIP_S = 10.0


class Table1Plan(NamedTuple):
    """A Table 1 schedule for one bench and the draws left out of it: one line each, saying why."""

    steps: tuple[Step, ...]
    dropped: tuple[str, ...]


def table1_plan(seed: int, limits: "BenchLimits | None" = None, n_cycles: int | None = None,
                duration_s: float | None = None, max_slip_s: float = MAX_SLIP_S) -> Table1Plan:
    """Draw cycles until `n_cycles` or the planned `duration_s` is reached (one of them is required).

    With the bench's `limits`, a draw whose launch cannot synchronise on its drivetrain
    (protocols.limits.launch_problem) is dropped with a note and the next one drawn, and a launch counts its time to
    synchronise towards `duration_s` (so the run lasts at least that long); without, every draw is kept and a
    launch counts its maximum slip time (the paper's raw draws, for the batch simulator's datasets).
    """
    if (n_cycles is None) == (duration_s is None):
        raise ValueError("give exactly one of n_cycles or duration_s")
    if limits is not None:
        from protocols.limits import launch_problem, with_launch_estimates
    rng = np.random.default_rng(seed)
    steps: list[Step] = []
    dropped: list[str] = []
    planned, cycle = 0.0, 0
    while (n_cycles is not None and cycle < n_cycles) or (duration_s is not None and planned < duration_s):
        speed = float(rng.choice(ENGINE_SPEEDS_RPM))
        torque = float(rng.choice(CLUTCH_TORQUES_NM))
        load = float(rng.choice(LOAD_TORQUES_NM))
        cooldown = float(rng.choice(COOLDOWN_S))
        launch = Step("launch", max_slip_s, speed, torque, load, cycle)
        if limits is not None:
            why = launch_problem(launch, limits)
            if why is not None:
                dropped.append(f"draw {cycle + len(dropped)} ({speed:g} rpm, clutch {torque:g} N*m, load {load:g} "
                               f"N*m) dropped: launch {why}")
                continue
            launch = with_launch_estimates((launch,), limits)[0]
        steps += [
            launch,
            Step("drive", cooldown / 2, speed, torque, load, cycle),
            Step("open", cooldown / 2, speed, 0.0, load, cycle),
        ]
        planned += launch.expected_s + cooldown
        cycle += 1
    return Table1Plan(tuple(steps), tuple(dropped))


def table1_schedule(seed: int, n_cycles: int | None = None, duration_s: float | None = None,
                    max_slip_s: float = MAX_SLIP_S) -> tuple[Step, ...]:
    """The raw Table 1 draws (every draw kept, launches planned at their maximum slip time): `table1_plan` without
    a bench."""
    return table1_plan(seed, None, n_cycles, duration_s, max_slip_s).steps
