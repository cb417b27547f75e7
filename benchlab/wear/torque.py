"""Clutch torque, eq. (1): T_c = z·r·μ(F_N, Δω, ϑ_fl)·F_N(s_c, s_w, ϑ_c), and μ estimated from measured torque."""

from __future__ import annotations

import numpy as np
import pandas as pd

from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.energy import held

ACTUATOR_CHANNEL = "actuator_position"
#: μ is estimated only where the clamp force is at least this share of the spring force (avoids 0/0 near open).
MIN_FORCE_SHARE = 0.05

Array = float | np.ndarray


def total_wear_mm(spec: ClutchSpec, wear_plate_mm: Array, wear_flywheel_mm: Array) -> Array:
    """Axial wear of the whole disc pack (all faces), the spring's travel s_w from new."""
    return spec.faces_per_side * (np.asarray(wear_plate_mm) + np.asarray(wear_flywheel_mm))


def normal_force(spec: ClutchSpec, total_wear: Array, spring_temperature_c: Array,
                 position_mm: Array | None = None) -> Array:
    """F_N(s_c, s_w, ϑ_c) in N: spring curve over wear × temperature factor × actuator release factor."""
    force = spec.maps["spring"](total_wear) * spec.maps["spring_temperature"](spring_temperature_c)
    return force if position_mm is None else force * spec.maps["actuator"](position_mm)


def friction_coefficient(spec: ClutchSpec, lining_temperature_c: Array, slip: Array, force_n: Array,
                         loss: Array) -> Array:
    """μ(F_N, Δω, ϑ_fl) of one side, reduced by that side's accumulated fractional loss."""
    return (spec.maps["friction"](lining_temperature_c) * spec.maps["friction_slip"](np.abs(slip))
            * spec.maps["friction_force"](force_n) * (1.0 - np.asarray(loss)))


def clutch_torque(spec: ClutchSpec, force_n: Array, mu_plate: Array, mu_flywheel: Array) -> Array:
    """T_c = z·r·μ·F_N with μ the mean of the two sides' coefficients (half the faces on each side)."""
    return spec.faces * spec.mean_radius_m * force_n * 0.5 * (np.asarray(mu_plate) + np.asarray(mu_flywheel))


def transmissible_torque(spec: ClutchSpec, wear_plate_mm: Array, wear_flywheel_mm: Array, loss_plate: Array,
                         loss_flywheel: Array) -> Array:
    """Torque the closed clutch holds at its rating temperature (locked, actuator released): the health measure."""
    t = spec.rating_temperature_c
    force = normal_force(spec, total_wear_mm(spec, wear_plate_mm, wear_flywheel_mm), t)
    return clutch_torque(spec, force, friction_coefficient(spec, t, 0.0, force, loss_plate),
                         friction_coefficient(spec, t, 0.0, force, loss_flywheel))


def estimate_mu(run: pd.DataFrame, spec: ClutchSpec, slipping: np.ndarray, spring_temperature_c: np.ndarray,
                total_wear: np.ndarray) -> np.ndarray | None:
    """μ̂ = |T_c| / (z·r·F_N(s_c, s_w, ϑ_c)) while slipping, NaN elsewhere; None if the run has no actuator position."""
    if ACTUATOR_CHANNEL not in run.columns or run[ACTUATOR_CHANNEL].isna().all():
        return None
    spring = normal_force(spec, total_wear, spring_temperature_c)
    force = spring * spec.maps["actuator"](held(run, ACTUATOR_CHANNEL))
    usable = slipping & (force >= MIN_FORCE_SHARE * spring) & run[ACTUATOR_CHANNEL].notna().to_numpy()
    mu = np.full(len(run), np.nan)
    mu[usable] = np.abs(held(run, "clutch_torque")[usable]) / (spec.faces * spec.mean_radius_m * force[usable])
    return mu

