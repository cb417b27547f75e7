"""Validation protocol (paper, Fig. 5): long cool-downs with engine speed or clutch state varying, plus
fresh Table 1 draws with another seed.

Each long cool-down starts from a hot clutch (pulsed heating until the flywheel reaches `hot_c`) and lasts
well beyond 120 s, with the engine speed or the clutch state changing during it: the situation where a
constant convection resistance is wrong. Then `table1_cycles` Table 1 cycles drawn with `seed + 1000`.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.schedule import Condition, Step
from protocols.table1 import table1_schedule

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


def validation_schedule(seed: int, config: ValidationConfig = ValidationConfig(),
                        n_cycles: int | None = None) -> tuple[Step, ...]:
    """Long varying cool-downs (cycles 0..2), then Table 1 cycles with another seed (cycles 3..)."""
    cfg = config
    steps: list[Step] = []
    hot = Condition("T_flywheel", ">=", cfg.hot_c)
    profiles = _profiles(cfg)
    for i, (name, segments) in enumerate(profiles):
        steps.append(Step("heat", 3600.0, cfg.heat_speed_rpm, cfg.heat_torque_nm, cfg.hold_load_nm, i, until=(hot,),
                          estimate_s=600.0, pulse_s=cfg.pulse_s, rest_s=cfg.rest_s, label="heat"))
        clamped = False
        for phase, rpm in segments:
            if phase == "drive" and not clamped:
                steps.append(Step("launch", 5.0, rpm, cfg.launch_torque_nm, 0.0, i, label="validation_cooldown"))
            if phase == "drive":
                steps.append(Step("drive", cfg.segment_s, rpm, cfg.launch_torque_nm, 0.0, i, label="validation_cooldown"))
            else:
                steps.append(Step("open", cfg.segment_s, rpm, 0.0, cfg.hold_load_nm, i, label="validation_cooldown"))
            clamped = phase == "drive"
    cycles = cfg.table1_cycles if n_cycles is None else n_cycles
    offset = len(profiles)
    for s in table1_schedule(seed + SEED_OFFSET, n_cycles=cycles):
        steps.append(Step(s.phase, s.duration_s, s.engine_speed_rpm, s.clutch_torque_nm, s.load_torque_nm,
                          s.cycle + offset, label="table1"))
    return tuple(steps)
