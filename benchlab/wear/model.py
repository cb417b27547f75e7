"""Wear law, eq. (3): lining height and μ loss per side from friction energy and lining temperature.

Per face, Δs_w = k(ϑ)·ΔE / A (k the specific wear rate in mm³/J, A the face area) and Δδ = d(ϑ)·ΔE
(d the μ loss per MJ); ΔE is the side's share of P·dt spread over that side's faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.state import SIDES, WearState


@dataclass(frozen=True)
class WearHistory:
    """Per-sample increments and the cumulative state after each sample (wear in mm per face, loss as a fraction)."""

    increments: dict[str, np.ndarray]
    cumulative: dict[str, np.ndarray]

    def final(self) -> WearState:
        """The wear state after the last sample."""
        return WearState(**{name: float(values[-1]) for name, values in self.cumulative.items()})


def side_increments(spec: ClutchSpec, side_power_w: np.ndarray, lining_temperature_c: np.ndarray,
                    dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(wear mm per face, fractional μ loss) added in each sample by one side's power at its lining temperature."""
    energy_per_face = np.asarray(side_power_w) * dt / spec.faces_per_side
    wear = spec.maps["wear_rate"](lining_temperature_c) * energy_per_face / spec.area_mm2
    loss = spec.maps["friction_loss"](lining_temperature_c) * energy_per_face * 1e-6
    return wear, loss


def wear_history(spec: ClutchSpec, power_w: np.ndarray, split: float, plate_temperature_c: np.ndarray,
                 flywheel_temperature_c: np.ndarray, dt: float, initial: WearState | None = None) -> WearHistory:
    """Integrate the wear law over a run: the plate side sees ϑ_P and `split`·P, the flywheel side ϑ_F and the rest."""
    initial = initial or spec.initial
    wear_p, loss_p = side_increments(spec, split * power_w, plate_temperature_c, dt)
    wear_f, loss_f = side_increments(spec, (1.0 - split) * power_w, flywheel_temperature_c, dt)
    increments = {"wear_plate_mm": wear_p, "wear_flywheel_mm": wear_f, "loss_plate": loss_p, "loss_flywheel": loss_f}
    cumulative = {name: getattr(initial, name) + np.cumsum(values) for name, values in increments.items()}
    return WearHistory(increments, cumulative)


#: The temperature paths a band is read at: estimate + k·σ for these k (both edges of ±2σ and between, so a
#: wear-rate map that is not monotone in the temperature is still bounded over the band).
BAND_STEPS = np.linspace(-2.0, 2.0, 9)


def wear_over_band(spec: ClutchSpec, power_w: np.ndarray, split: float, plate_c: np.ndarray, plate_std_k: np.ndarray,
                   flywheel_c: np.ndarray, flywheel_std_k: np.ndarray, dt: float) -> dict[str, tuple[float, float, float]]:
    """Wear per face this run (mm) per side: (at the estimate, least, most over the ±2σ band). The band is taken
    whole (every sample at the same k): an error that comes from the model is a bias that lasts, not noise that
    averages out, and a wear sum over a run inherits it in full."""
    finals: dict[str, list[float]] = {side: [] for side in SIDES}
    for k in (0.0, *BAND_STEPS):
        history = wear_history(spec, power_w, split, plate_c + k * plate_std_k, flywheel_c + k * flywheel_std_k, dt)
        for side in finals:
            finals[side].append(history.final().wear_mm(side) - spec.initial.wear_mm(side))
    return {side: (values[0], min(values), max(values)) for side, values in finals.items()}
