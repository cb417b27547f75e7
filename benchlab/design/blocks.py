"""The small library of feasible blocks a designed run is assembled from: each block heats the clutch by launches,
then holds one long cool-down at a chosen engine speed with the clutch clamped or open (the operating points of
eq. (11)); or, for the cool-down reading, heats to a steady flywheel first and cools to a temperature, as the
cool-down sweep reads its points (`steady_blocks`).

The launch blocks are open loop (fixed durations), so the design can predict them exactly with the bench's
drivetrain; the steady ones are closed loop, predicted as the model expects them to go
(`benchlab.design.fisher.open_loop`). Every block passes `protocols.limits.schedule_problems` on the bench it is
built for: a launch that cannot synchronise on the bench's drivetrain is never offered.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from protocols.cooldown_sweep import SweepConfig, cooldown_sweep_schedule
from protocols.estimates import Plant
from protocols.limits import BenchLimits, launch_problem, schedule_problems, with_launch_estimates
from protocols.schedule import Step

#: Engine speeds a cool-down is offered at (rpm), as far as the bench's limit allows: the cool-down sweep's grid.
COOLDOWN_SPEEDS_RPM = (500.0, 1000.0, 1500.0, 2000.0, 2500.0)
#: Cool-down lengths offered (s): long against the flywheel's time constant at the fastest convection.
COOLDOWN_LENGTHS_S = (300.0, 600.0, 900.0)
#: Heating launches before each cool-down, their speed and the time the shaft is given to stop after each.
HEAT_LAUNCHES = 4
#: A heating launch must be expected to synchronise within this share of its maximum slip time: the bench's
#: actuator builds its torque up over a few tenths of a second and the load's reaction is not exact, and a launch
#: planned at 8.2 of 10 s (2500 rpm, 50 N*m against 600 N*m) slipped to the time limit on the simulated bench in
#: 10 of 24 launches, then tripped the over-temperature interlocks.
SYNC_SHARE = 1 / 3
HEAT_SPEED_RPM = 2500.0
STOP_S = 10.0
#: Clutch torque that brings a shaft without load to the engine's speed for a clamped cool-down.
CLAMP_TORQUE_NM = 40.0
CLAMP_LAUNCH_S = 5.0


@dataclass(frozen=True)
class Block:
    """A candidate segment of a designed run: its name (what it does, in words) and its steps (cycle 0)."""

    name: str
    steps: tuple[Step, ...]

    @property
    def expected_s(self) -> float:
        return float(sum(s.expected_s for s in self.steps))


def heating_launch(limits: BenchLimits, speed_rpm: float = HEAT_SPEED_RPM) -> Step | None:
    """The launch that puts the most slip energy into the clutch within the bench's limits (the largest load the
    clutch still synchronises against well within its slip time, SYNC_SHARE; energy within the interlock), or None
    where no launch can."""
    speed = min(speed_rpm, limits.max_engine_speed_rpm)
    best: Step | None = None
    best_energy = 0.0
    from protocols.limits import launch_estimate

    for torque in (30.0, 40.0, 50.0, 65.0, 80.0, 100.0):
        if torque > limits.max_clutch_torque_nm:
            continue
        for load in (0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0):
            if load > limits.max_load_torque_nm:
                continue
            step = Step("launch", min(10.0, limits.max_slip_time_s), speed, torque, load, 0, label="heat")
            t_sync, energy, _ = launch_estimate(step, limits)
            robust = t_sync <= SYNC_SHARE * step.duration_s and energy <= 0.9 * limits.max_slip_energy_j
            if launch_problem(step, limits) is None and robust and energy > best_energy:
                best, best_energy = step, energy
    return best


def cooldown_steps(speed_rpm: float, clamped: bool, length_s: float) -> tuple[Step, ...]:
    """One cool-down at `speed_rpm` (label "cooldown", its operating point as the sweep's): clamped, the shaft
    turning with the engine (a launch without load first); open, the shaft standing (held by the load)."""
    state = 1.0 if clamped else 0.0
    point = (("engine_speed", speed_rpm), ("clutch_state", state), ("slip_speed", 0.0 if clamped else speed_rpm))
    if clamped:
        return (Step("launch", CLAMP_LAUNCH_S, speed_rpm, CLAMP_TORQUE_NM, 0.0, 0, label="prepare", point=point),
                Step("drive", length_s, speed_rpm, CLAMP_TORQUE_NM, 0.0, 0, label="cooldown", point=point))
    return (Step("open", length_s, speed_rpm, 0.0, 0.0, 0, label="cooldown", point=point),)


def candidate_blocks(limits: BenchLimits) -> list[Block]:
    """Every block the bench can run: heat by HEAT_LAUNCHES launches, then cool at each speed, clutch clamped or
    open, each of COOLDOWN_LENGTHS_S; blocks with a problem under the bench's limits left out."""
    launch = heating_launch(limits)
    if launch is None:
        return []
    stop = Step("open", STOP_S, launch.engine_speed_rpm, 0.0, launch.load_torque_nm, 0, label="heat")
    heat = (launch, stop) * HEAT_LAUNCHES
    blocks = []
    for speed in COOLDOWN_SPEEDS_RPM:
        if speed > limits.max_engine_speed_rpm:
            continue
        for clamped in (False, True):
            for length in COOLDOWN_LENGTHS_S:
                steps = with_launch_estimates(heat + cooldown_steps(speed, clamped, length), limits)
                if not schedule_problems(steps, limits):
                    state = "clamped" if clamped else "open"
                    blocks.append(Block(f"heat, cool {length:g} s at {speed:g} rpm clutch {state}", steps))
    return blocks


def steady_blocks(limits: BenchLimits, plant: Plant) -> list[Block]:
    """A block at each engine speed, clutch clamped or open, that reads its point as the cool-down sweep does: the
    sweep's own cycle (`protocols.cooldown_sweep`: pulsed heat until the flywheel is steady at the heat target,
    the point prepared, a cool-down until the flywheel reaches the cool target), timed on `plant` (the model) from
    rest; blocks with a problem under the bench's limits left out."""
    blocks = []
    for speed in COOLDOWN_SPEEDS_RPM:
        if speed > limits.max_engine_speed_rpm:
            continue
        for state in (0, 1):
            steps = with_launch_estimates(cooldown_sweep_schedule([(speed, state, None)], SweepConfig(), plant), limits)
            if not schedule_problems(steps, limits):
                sweep = SweepConfig()
                blocks.append(Block(f"heat to a steady {sweep.heat_target_c:g} degC, cool to {sweep.cool_target_c:g} "
                                    f"degC at {speed:g} rpm clutch {'clamped' if state else 'open'}", steps))
    return blocks


def steady_schedule(blocks: Sequence[Block], limits: BenchLimits, plant: Plant) -> tuple[Step, ...]:
    """Steady blocks one after the other: the sweep over their points, block i as cycle i, each heat-up and
    cool-down timed on `plant` where it follows the one before."""
    grid = [(b.steps[-1].engine_speed_rpm, int(dict(b.steps[-1].point)["clutch_state"]), None) for b in blocks]
    return with_launch_estimates(cooldown_sweep_schedule(grid, SweepConfig(), plant), limits)


def numbered(blocks: list[Block]) -> tuple[Step, ...]:
    """The blocks one after the other as a schedule, block i as cycle i (what resume continues from)."""
    return tuple(replace(step, cycle=i) for i, block in enumerate(blocks) for step in block.steps)
