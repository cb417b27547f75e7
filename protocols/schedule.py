"""Protocols as data: a schedule of load cycles and cool-downs that can be printed, checked and timed.

A schedule is a tuple of Steps; each Step holds set-points for a duration, the way the bench
controllers hold them (engine speed by the drive motor, clutch torque by the actuator, load
torque by the load machine). Nothing here moves hardware.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Step:
    """Set-points held for `duration_s`; `phase` names it for events and summaries.

    phase "launch" clamps the clutch at `clutch_torque_nm` until synchronous (or a slip limit);
    "drive" keeps it clamped and locked; "open" opens it; the load machine applies `load_torque_nm`.
    """

    phase: str
    duration_s: float
    engine_speed_rpm: float
    clutch_torque_nm: float = 0.0
    load_torque_nm: float = 0.0
    cycle: int = -1

    def as_dict(self) -> dict[str, float | str | int]:
        return asdict(self)


PHASES = ("launch", "drive", "open")


def duration_s(steps: tuple[Step, ...]) -> float:
    """Planned duration; a launch's duration is its maximum slip time."""
    return float(sum(step.duration_s for step in steps))
