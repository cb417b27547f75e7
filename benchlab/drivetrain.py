"""Drivetrain facts and formulas, in one place: rpm in rad/s, the bench's gear ratio and load inertia, friction
power (eq. 4) and when a clutch counts as slipping by its speeds.

The bench configuration's `[drivetrain]` table fills `DrivetrainFacts`; the limits' launch estimates, the CAN
bench's input-shaft speed and the simulated bench's shafts all read the same object. Imports nothing heavy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

#: rad/s per rpm.
RPM = math.pi / 30.0
#: Slip (rpm) beyond which a clamped clutch counts as slipping where no other evidence says so (speed noise
#: at synchronisation stays below it).
SLIP_THRESHOLD_RPM = 5.0

Value = TypeVar("Value")  # a float for one frame, a numpy array for a grid


@dataclass(frozen=True)
class DrivetrainFacts:
    """Gear ratio between the input shaft and the load machine, and the load inertia at the load machine."""

    gear_ratio: float = 15.0
    load_inertia_kgm2: float = 70.0

    @property
    def inertia_at_clutch(self) -> float:
        """The load inertia seen from the clutch (kg·m²): divided by the ratio squared."""
        return self.load_inertia_kgm2 / self.gear_ratio ** 2


def friction_power(torque_nm: Value, engine_rpm: Value, clutch_rpm: Value, slipping: Value) -> Value:
    """P = |T_c · Δω| (eq. 4) in W where `slipping` (bool or 0/1), else 0; NaN where torque or a speed is unknown.

    Plain arithmetic, so one frame (floats) and a whole grid (arrays) take the same formula.
    """
    return abs(torque_nm * (engine_rpm - clutch_rpm) * RPM) * slipping


def slipping_by_speed(engine_rpm: Value, clutch_rpm: Value) -> Value:
    """Whether the two sides turn apart by more than the slip threshold (a clamped clutch then slips)."""
    return abs(engine_rpm - clutch_rpm) > SLIP_THRESHOLD_RPM
