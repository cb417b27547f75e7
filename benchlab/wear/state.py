"""The wear state of a clutch: lining wear and friction-coefficient loss per side (eq. 3: w = f_w(μ, s_w))."""

from __future__ import annotations

from dataclasses import dataclass

SIDES = ("plate", "flywheel")


@dataclass(frozen=True)
class WearState:
    """Lining height lost per face (mm) and fractional μ loss, on the pressure-plate and the flywheel side."""

    wear_plate_mm: float = 0.0
    wear_flywheel_mm: float = 0.0
    loss_plate: float = 0.0
    loss_flywheel: float = 0.0

    def wear_mm(self, side: str) -> float:
        return self.wear_plate_mm if side == "plate" else self.wear_flywheel_mm

    def loss(self, side: str) -> float:
        return self.loss_plate if side == "plate" else self.loss_flywheel
