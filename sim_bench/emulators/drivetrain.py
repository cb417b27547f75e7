"""Physics behind the CAN controller emulators: the `DrivetrainProvider` interface and a stand-alone default.

The default tracks each set-point with a first-order lag and integrates the load inertia (`DrivetrainFacts`) under
clutch and load torque, locking the clutch when the speeds meet. A thermal plant / bench model replaces it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from benchlab.drivetrain import RPM, DrivetrainFacts
from drivers.can_signals import CLAMP_CLAMPED, CLAMP_OPEN, CLAMP_SLIPPING


@dataclass(frozen=True, slots=True)
class DrivetrainActuals:
    """Actual values the controllers report (rpm, N·m, mm; clamp state per drivers.can_signals), one per frame."""

    drive_speed_rpm: np.ndarray
    drive_torque_nm: np.ndarray
    clutch_torque_nm: np.ndarray
    clutch_position_mm: np.ndarray
    clamp_state: np.ndarray
    load_speed_rpm: np.ndarray
    load_torque_nm: np.ndarray


_FIELDS = tuple(DrivetrainActuals.__dataclass_fields__)


class DrivetrainProvider(Protocol):
    """Set-points in from the controllers, actual values out.

    `advance(t)` moves the state to absolute time `t` (s); set-points given after it hold from `t` on.
    `actuals_matrix(times)` are the actual values at increasing times >= the last `advance`, one row per
    DrivetrainActuals field (in field order) and one column per time (frame), computed with the set-points as
    they are; `actuals_at(times)` the same as DrivetrainActuals (the emulator takes the matrix: no copy).
    """

    def set_drive_speed(self, rpm: float) -> None: ...
    def set_clutch(self, torque_nm: float, open_request: bool) -> None: ...
    def set_load_torque(self, torque_nm: float) -> None: ...
    def advance(self, t: float) -> None: ...
    def actuals_matrix(self, times: np.ndarray) -> np.ndarray: ...
    def actuals_at(self, times: np.ndarray) -> DrivetrainActuals: ...


class FirstOrderDrivetrain:
    """Drive speed, clutch torque and load torque follow their set-points with lags; load speed integrates."""

    def __init__(self, *, t0: float = 0.0, tau_speed_s: float = 0.3, tau_torque_s: float = 0.05,
                 load_inertia: float = DrivetrainFacts.load_inertia_kgm2, stroke_mm: float = 8.0,
                 full_torque_nm: float = 100.0, max_step_s: float = 0.01) -> None:
        self.t = t0
        self.tau_speed_s, self.tau_torque_s, self.inertia = tau_speed_s, tau_torque_s, load_inertia
        self.stroke_mm, self.full_torque_nm, self.max_step_s = stroke_mm, full_torque_nm, max_step_s
        self.speed_sp = self.clutch_sp = self.load_sp = 0.0
        self.open_request = True
        self.w_drive = self.w_load = 0.0          # rad/s
        self.t_clutch = self.t_load = 0.0         # N·m, actuator outputs (capacity / load torque)
        self.transmitted = 0.0
        self.locked = False

    def set_drive_speed(self, rpm: float) -> None:
        self.speed_sp = rpm

    def set_clutch(self, torque_nm: float, open_request: bool) -> None:
        self.clutch_sp, self.open_request = (0.0 if open_request else max(0.0, torque_nm)), open_request

    def set_load_torque(self, torque_nm: float) -> None:
        self.load_sp = torque_nm

    def advance(self, t: float) -> None:
        while self.t < t:
            dt = min(self.max_step_s, t - self.t)
            self._step(dt)
            self.t += dt

    def actuals_matrix(self, times: np.ndarray) -> np.ndarray:
        rows = []
        for t in times:
            self.advance(float(t))
            rows.append(self._actuals())
        return np.array(rows, dtype=float).reshape(len(rows), len(_FIELDS)).T

    def actuals_at(self, times: np.ndarray) -> DrivetrainActuals:
        return DrivetrainActuals(*self.actuals_matrix(times))

    def _actuals(self) -> tuple[float, ...]:
        if self.open_request and self.t_clutch < 0.5:
            clamp = CLAMP_OPEN
        else:
            clamp = CLAMP_CLAMPED if self.locked else CLAMP_SLIPPING
        position = self.stroke_mm * max(0.0, 1.0 - self.t_clutch / self.full_torque_nm)
        return (self.w_drive / RPM, self.transmitted, abs(self.transmitted), position, clamp,
                self.w_load / RPM, self.t_load)

    def _step(self, dt: float) -> None:
        a_speed = 1.0 - math.exp(-dt / self.tau_speed_s)
        a_torque = 1.0 - math.exp(-dt / self.tau_torque_s)
        self.w_drive += a_speed * (self.speed_sp * RPM - self.w_drive)
        self.t_clutch += a_torque * (self.clutch_sp - self.t_clutch)
        self.t_load += a_torque * (self.load_sp - self.t_load)
        if self.locked and abs(self.t_load) <= self.t_clutch:
            self.w_load, self.transmitted = self.w_drive, self.t_load
            return
        slip = self.w_drive - self.w_load
        self.transmitted = math.copysign(self.t_clutch, slip) if slip else 0.0
        w_new = max(0.0, self.w_load + dt * (self.transmitted - self.t_load) / self.inertia)
        self.locked = self.t_clutch > 0.5 and (self.w_drive - w_new) * slip <= 0.0
        self.w_load = self.w_drive if self.locked else w_new
