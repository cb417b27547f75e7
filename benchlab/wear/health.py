"""Health state: the clutch is worn when its transmissible torque falls below T_e,max or a lining reaches its limit."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.state import WearState
from benchlab.wear.torque import total_wear_mm, transmissible_torque


@dataclass(frozen=True)
class Health:
    """Torque and lining margins of one wear state; `health` is the smaller remaining share (1 new, 0 worn)."""

    transmissible_torque_Nm: float
    new_torque_Nm: float
    max_engine_torque_Nm: float
    height_plate_mm: float
    height_flywheel_mm: float
    min_height_mm: float
    total_wear_mm: float
    health: float
    worn: bool
    limited_by: str

    def as_dict(self) -> dict[str, float | bool | str]:
        return asdict(self)


def worn(spec: ClutchSpec, wear_plate_mm: np.ndarray, wear_flywheel_mm: np.ndarray, loss_plate: np.ndarray,
         loss_flywheel: np.ndarray) -> np.ndarray:
    """Element-wise: torque below T_e,max or either lining at or below its minimum height."""
    limit = spec.height_mm - spec.min_height_mm
    torque = transmissible_torque(spec, wear_plate_mm, wear_flywheel_mm, loss_plate, loss_flywheel)
    return (torque < spec.max_engine_torque_nm) | (wear_plate_mm >= limit) | (wear_flywheel_mm >= limit)


def assess(spec: ClutchSpec, state: WearState) -> Health:
    """Health of a clutch in `state`, measured at the clutch file's rating temperature."""
    torque = float(transmissible_torque(spec, state.wear_plate_mm, state.wear_flywheel_mm, state.loss_plate,
                                        state.loss_flywheel))
    new = float(transmissible_torque(spec, 0.0, 0.0, 0.0, 0.0))
    margin_torque = (torque - spec.max_engine_torque_nm) / max(new - spec.max_engine_torque_nm, 1e-12)
    reserve = spec.height_mm - spec.min_height_mm
    margin_height = 1.0 - max(state.wear_plate_mm, state.wear_flywheel_mm) / reserve
    is_worn = bool(worn(spec, np.array(state.wear_plate_mm), np.array(state.wear_flywheel_mm),
                        np.array(state.loss_plate), np.array(state.loss_flywheel)))
    return Health(
        transmissible_torque_Nm=torque, new_torque_Nm=new, max_engine_torque_Nm=spec.max_engine_torque_nm,
        height_plate_mm=spec.height_mm - state.wear_plate_mm,
        height_flywheel_mm=spec.height_mm - state.wear_flywheel_mm,
        min_height_mm=spec.min_height_mm,
        total_wear_mm=float(total_wear_mm(spec, state.wear_plate_mm, state.wear_flywheel_mm)),
        health=float(np.clip(min(margin_torque, margin_height), 0.0, 1.0)), worn=is_worn,
        limited_by="torque" if margin_torque <= margin_height else "lining_height")
