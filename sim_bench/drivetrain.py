"""Bench drivetrain: drive motor (speed control), clutch (torque control), load machine on a 70 kg·m² inertia.

Between set-point changes the torques are constant, so the input-shaft speed moves with constant
acceleration: the drivetrain advances analytically, sample by sample in numpy, never by small
integration steps. Speeds in rpm outside, rad/s inside.
"""

from __future__ import annotations

import numpy as np
from benchlab.jit import njit

from benchlab.drivetrain import RPM, DrivetrainFacts

SYNC_TOLERANCE_RPM = 1e-6


CHANNELS = ("engine_speed", "clutch_speed", "clutch_torque", "clutch_state", "friction_power", "load_torque")


class Drivetrain:
    """State of the shafts plus the controllers' set-points; `advance` returns sampled channels."""

    def __init__(self, config: DrivetrainFacts = DrivetrainFacts(), engine_rpm: float = 0.0) -> None:
        self.config = config
        self.engine_rpm = engine_rpm
        self.clutch_rpm = 0.0
        self.clamped = False
        self.torque_setpoint_nm = 0.0
        self.load_torque_nm = 0.0
        self.torque_factor = 1.0  # μ(ϑ)/μ_cal: transmitted torque per N·m commanded (the plant's friction law)

    @property
    def slipping(self) -> bool:
        return self.clamped and abs(self.engine_rpm - self.clutch_rpm) > SYNC_TOLERANCE_RPM

    def set_points(self, engine_rpm: float, clamped: bool, torque_nm: float, load_nm: float) -> None:
        """Apply controller set-points; they hold until the next call."""
        self.engine_rpm, self.clamped = float(engine_rpm), bool(clamped)
        self.torque_setpoint_nm, self.load_torque_nm = float(torque_nm), float(load_nm)

    def _acceleration(self) -> tuple[float, float]:
        """(transmitted clutch torque N·m, input-shaft acceleration rad/s²) in the current mode."""
        reaction = self.load_torque_nm / self.config.gear_ratio
        if not self.clamped:
            transmitted = 0.0
        elif self.slipping:
            transmitted = float(np.sign(self.engine_rpm - self.clutch_rpm)) * self.torque_setpoint_nm * self.torque_factor
        else:
            return reaction, 0.0
        accel = (transmitted - reaction) / self.config.inertia_at_clutch
        if self.clutch_rpm <= 0 and accel < 0:  # a stopped vehicle does not roll back
            accel = 0.0
        return transmitted, accel

    def advance(self, n: int, dt: float, stop_at_sync: bool = False) -> dict[str, np.ndarray]:
        """Sample the next n steps (values at the start of each step); stop early at sync if asked."""
        matrix = np.empty((len(CHANNELS), n))
        columns = dict(zip(CHANNELS, matrix))
        k = 0
        while k < n:
            transmitted, accel = self._acceleration()
            m = n - k
            if self.slipping and accel != 0.0:
                gap = (self.engine_rpm - self.clutch_rpm) * RPM
                if gap * accel > 0:  # moving towards synchronism: stop the piece there
                    m = min(m, max(1, int(np.ceil(gap / accel / dt))))
            elif not self.clamped and self.clutch_rpm > 0 and accel < 0:
                m = min(m, max(1, int(np.ceil(self.clutch_rpm * RPM / -accel / dt))))
            # never overshoot synchronism: clip at the engine speed (1: from below, -1: from above, 0: no clip)
            clip = (1 if accel > 0 else -1) if self.slipping and accel != 0.0 else 0
            _fill_piece(matrix, k, m, dt, self.clutch_rpm * RPM, accel, clip, self.engine_rpm, self.engine_rpm * RPM,
                        transmitted, self.clamped, self.load_torque_nm)
            was_slipping = self.slipping
            end_omega = self.clutch_rpm * RPM + accel * m * dt
            if was_slipping and accel != 0.0 and (end_omega - self.engine_rpm * RPM) * accel >= 0:
                end_omega = self.engine_rpm * RPM  # synchronised: the clutch locks
            self.clutch_rpm = max(end_omega, 0.0) / RPM
            k += m
            if stop_at_sync and was_slipping and not self.slipping:
                return {name: col[:k] for name, col in columns.items()}
        return columns


@njit(cache=True, nogil=True)
def _fill_piece(matrix: np.ndarray, k: int, m: int, dt: float, omega0: float, accel: float, clip: int,
                engine_rpm: float, engine_omega: float, transmitted: float, clamped: bool,
                load_nm: float) -> None:  # pragma: no cover - compiled
    """Samples k .. k+m-1 of the CHANNELS rows of `matrix` for one piece of constant acceleration: the input shaft
    from omega0 (rad/s), clipped at the engine speed (`clip`) and at 0, slip and friction power; the numpy
    expressions these replace, element by element (np.minimum/np.maximum keep the first operand on ties)."""
    for i in range(m):
        omega = omega0 + accel * (i * dt)
        if clip > 0:
            omega = omega if omega <= engine_omega else engine_omega
        elif clip < 0:
            omega = omega if omega >= engine_omega else engine_omega
        omega = omega if omega >= 0.0 else 0.0
        slip = engine_omega - omega
        slipping = clamped and abs(slip) > SYNC_TOLERANCE_RPM * RPM
        matrix[0, k + i] = engine_rpm
        matrix[1, k + i] = omega / RPM
        matrix[2, k + i] = transmitted
        matrix[3, k + i] = 1.0 if clamped else 0.0
        matrix[4, k + i] = abs(transmitted * slip) if slipping else 0.0
        matrix[5, k + i] = load_nm
