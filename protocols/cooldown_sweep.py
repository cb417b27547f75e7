"""Cool-down sweep (paper, Fig. 3): heat to a steady 70 °C, cool to 60 °C at one operating point, repeat.

For each grid point (engine speed ω_e, clutch state S, slip speed Δω = ω_e − ω_c):

1. **heat** with a constant load: the output shaft is held by the load machine, the clutch slips in
   pulses of `pulse_s` at `heat_torque_nm` with `rest_s` open in between (each pulse is one engagement,
   well inside the slip-time and slip-energy interlocks); a pulse starts only while the flywheel is below
   the target, until the flywheel is *steady at the target*: the mean of the last `window_s` within
   ±`band_k` of 70 °C and the means of the window's halves no more than `drift_k` apart.
2. **prepare** the point: for S = 1 (Δω = 0) a launch to synchronism at ω_e with no load; for S = 0
   with a turning shaft (Δω ≠ ω_e) a launch at ω_c = ω_e − Δω, so the shaft coasts at ω_c once opened.
3. **cool-down** (label "cooldown") at (ω_e, S, Δω) until the flywheel is at or below 60 °C.

Each cool-down gives a convection resistance R_FA = R_PA with its uncertainty (benchlab.identify.cooldown).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from protocols.estimates import ROOM_C, Plant, cool_estimate_s, heat_estimate_s, timed
from protocols.schedule import Condition, Step

DEFAULT_GRID: tuple[tuple[float, int, float | None], ...] = (
    (500.0, 1, 0.0), (1000.0, 1, 0.0), (1500.0, 1, 0.0), (2500.0, 1, 0.0),
    (500.0, 0, None), (1000.0, 0, None), (1500.0, 0, None), (2500.0, 0, None),
)


@dataclass(frozen=True)
class SweepConfig:
    """Targets and heating of the sweep; the grid is a list of (engine rpm, S, slip rpm or None = ω_e)."""

    heat_target_c: float = 70.0
    cool_target_c: float = 60.0
    heat_speed_rpm: float = 1500.0
    heat_torque_nm: float = 20.0
    hold_load_nm: float = 500.0
    pulse_s: float = 8.0
    rest_s: float = 4.0
    band_k: float = 1.0
    window_s: float = 120.0
    drift_k: float = 0.3
    launch_torque_nm: float = 40.0
    heat_timeout_s: float = 3600.0
    cool_timeout_s: float = 3600.0


def parse_grid(text: str) -> tuple[tuple[float, int, float | None], ...]:
    """'1000:1,1000:0,1500:0:500' -> points (rpm, S[, slip rpm]); ValueError naming the bad item."""
    points = []
    for item in (p.strip() for p in text.split(",") if p.strip()):
        parts = item.split(":")
        try:
            if len(parts) not in (2, 3):
                raise ValueError
            rpm, state = float(parts[0]), int(parts[1])
            slip = float(parts[2]) if len(parts) == 3 else None
        except ValueError:
            raise ValueError(f"grid item {item!r}: expected RPM:S or RPM:S:SLIP_RPM") from None
        if state not in (0, 1) or not math.isfinite(rpm) or rpm < 0:
            raise ValueError(f"grid item {item!r}: S must be 0 or 1 and RPM >= 0")
        if state == 1 and slip not in (None, 0.0):
            raise ValueError(f"grid item {item!r}: a clamped clutch (S=1) cannot slip during a cool-down")
        points.append((rpm, state, 0.0 if state == 1 else slip))
    if not points:
        raise ValueError("empty grid")
    return tuple(points)


def cooldown_sweep_schedule(grid: Sequence[tuple[float, int, float | None]] = DEFAULT_GRID,
                            config: SweepConfig = SweepConfig(), plant: Plant | None = None) -> tuple[Step, ...]:
    """The sweep over `grid`; cycle i is grid point i. Its heat-ups and cool-downs are expected to last what they
    last on `plant` (simulated: protocols.estimates.timed), without one what the paper's closed forms say."""
    cfg = config
    steps: list[Step] = []
    steady = Condition("T_flywheel", "steady", cfg.heat_target_c, cfg.band_k, cfg.window_s, cfg.drift_k)
    cooled = Condition("T_flywheel", "<=", cfg.cool_target_c)
    for i, (rpm, state, slip) in enumerate(grid):
        slip = rpm if (state == 0 and slip is None) else (0.0 if slip is None else slip)
        shaft = rpm - slip
        point = (("engine_speed", float(rpm)), ("clutch_state", float(state)), ("slip_speed", float(slip)))
        heat_s = heat_estimate_s(
            ROOM_C if i == 0 else cfg.cool_target_c, cfg.heat_target_c, cfg.heat_speed_rpm, cfg.heat_torque_nm,
            cfg.pulse_s, cfg.rest_s, cfg.window_s)
        steps.append(Step("heat", cfg.heat_timeout_s, cfg.heat_speed_rpm, cfg.heat_torque_nm, cfg.hold_load_nm, i,
                          until=(steady,), estimate_s=round(min(heat_s, cfg.heat_timeout_s), 1), pulse_s=cfg.pulse_s,
                          rest_s=cfg.rest_s, label="heat", point=point))
        cool_s = cool_estimate_s(rpm, state, cfg.heat_target_c, cfg.cool_target_c)
        estimate = round(min(cfg.cool_timeout_s, cool_s), 1)
        if state == 1:
            steps.append(Step("launch", 5.0, rpm, cfg.launch_torque_nm, 0.0, i, label="prepare", point=point))
            steps.append(Step("drive", cfg.cool_timeout_s, rpm, cfg.launch_torque_nm, 0.0, i, until=(cooled,),
                              estimate_s=estimate, label="cooldown", point=point))
        elif shaft > 0:
            steps.append(Step("launch", 5.0, shaft, cfg.launch_torque_nm, 0.0, i, label="prepare", point=point))
            steps.append(Step("open", cfg.cool_timeout_s, rpm, 0.0, 0.0, i, until=(cooled,),
                              estimate_s=estimate, label="cooldown", point=point))
        else:
            steps.append(Step("open", cfg.cool_timeout_s, rpm, 0.0, cfg.hold_load_nm, i, until=(cooled,),
                              estimate_s=estimate, label="cooldown", point=point))
    return tuple(steps) if plant is None else timed(steps, plant)
