"""Validation protocol (paper, Fig. 5): long cool-downs with engine speed or clutch state varying, plus
fresh Table 1 draws with another seed.

Each long cool-down starts from a hot clutch (pulsed heating until the flywheel reaches `hot_c`) and lasts
well beyond 120 s, with the engine speed or the clutch state changing during it: the situation where a
constant convection resistance is wrong. Then `table1_cycles` Table 1 cycles drawn with `seed + 1000`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from protocols.estimates import ROOM_C, cooled_to, heat_estimate_s
from protocols.schedule import Condition, Step
from protocols.table1 import Table1Plan, table1_plan

if TYPE_CHECKING:
    from protocols.limits import BenchLimits

SEED_OFFSET = 1000


@dataclass(frozen=True)
class ValidationConfig:
    hot_c: float = 70.0
    segment_s: float = 200.0
    heat_speed_rpm: float = 1500.0
    heat_torque_nm: float = 20.0
    hold_load_nm: float = 500.0
    pulse_s: float = 8.0
    rest_s: float = 4.0
    launch_torque_nm: float = 40.0
    table1_cycles: int = 20


def _profiles(cfg: ValidationConfig) -> list[tuple[str, list[tuple[str, float]]]]:
    """(name, [(phase, engine rpm), ...]) each segment lasting `segment_s`; "drive" = clamped, "open" = stopped."""
    return [
        ("engine speed steps, clutch open (vehicle stopped)", [("open", 1000.0), ("open", 2000.0), ("open", 1000.0)]),
        ("engine speed steps, clutch closed (driving)", [("drive", 1000.0), ("drive", 2000.0), ("drive", 1000.0)]),
        ("clutch state toggles at 1500 rpm", [("open", 1500.0), ("drive", 1500.0), ("open", 1500.0)]),
    ]


def validation_plan(seed: int, config: ValidationConfig = ValidationConfig(), n_cycles: int | None = None,
                    limits: "BenchLimits | None" = None) -> Table1Plan:
    """Long varying cool-downs (cycles 0..2), then Table 1 cycles with another seed (cycles 3..), drawn for the
    bench's `limits` as `table1_plan` draws them (its dropped draws returned with the steps)."""
    cfg = config
    steps: list[Step] = []
    hot = Condition("T_flywheel", ">=", cfg.hot_c)
    profiles = _profiles(cfg)
    flywheel_c = ROOM_C  # expected at each heat-up's start, for its estimate
    for i, (name, segments) in enumerate(profiles):
        heat_s = heat_estimate_s(flywheel_c, cfg.hot_c, cfg.heat_speed_rpm, cfg.heat_torque_nm, cfg.pulse_s, cfg.rest_s)
        steps.append(Step("heat", 3600.0, cfg.heat_speed_rpm, cfg.heat_torque_nm, cfg.hold_load_nm, i, until=(hot,),
                          estimate_s=round(min(heat_s, 3600.0), 1), pulse_s=cfg.pulse_s, rest_s=cfg.rest_s,
                          label="heat"))
        clamped = False
        flywheel_c = cfg.hot_c
        for phase, rpm in segments:
            if phase == "drive" and not clamped:
                steps.append(Step("launch", 5.0, rpm, cfg.launch_torque_nm, 0.0, i, label="validation_cooldown"))
            if phase == "drive":
                steps.append(Step("drive", cfg.segment_s, rpm, cfg.launch_torque_nm, 0.0, i, label="validation_cooldown"))
            else:
                steps.append(Step("open", cfg.segment_s, rpm, 0.0, cfg.hold_load_nm, i, label="validation_cooldown"))
            clamped = phase == "drive"
            flywheel_c = cooled_to(flywheel_c, rpm, int(clamped), cfg.segment_s)
    cycles = cfg.table1_cycles if n_cycles is None else n_cycles
    offset = len(profiles)
    table1 = table1_plan(seed + SEED_OFFSET, limits, n_cycles=cycles)
    for s in table1.steps:
        steps.append(Step(s.phase, s.duration_s, s.engine_speed_rpm, s.clutch_torque_nm, s.load_torque_nm,
                          s.cycle + offset, estimate_s=s.estimate_s, label="table1"))
    return Table1Plan(tuple(steps), table1.dropped)


def validation_schedule(seed: int, config: ValidationConfig = ValidationConfig(),
                        n_cycles: int | None = None) -> tuple[Step, ...]:
    """The validation protocol's steps without a bench (every Table 1 draw kept): `validation_plan`'s."""
    return validation_plan(seed, config, n_cycles).steps
