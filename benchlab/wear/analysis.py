"""`analyse_wear`: friction energy, engagements, lining temperatures, wear, health and remaining life of one run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.model.params import ModelParams
from benchlab.wear.clutchfile import ClutchSpec, default_clutch
from benchlab.wear.defaults import DEFAULT_HORIZON, DEFAULT_PATHS
from benchlab.wear.energy import (DEFAULT_GAP_S, engagement_spans, engagement_table, friction_energy,
                                  held, run_friction_power, slip_rad_s)
from benchlab.wear.health import Health, assess
from benchlab.wear.life import STATE_FIELDS, LifeDistribution, remaining_life
from benchlab.wear.model import WearHistory, wear_history
from benchlab.wear.state import SIDES, WearState
from benchlab.wear.thermal import heat_split, lining_temperatures
from benchlab.wear.torque import (ACTUATOR_CHANNEL, estimate_mu, friction_coefficient, normal_force, total_wear_mm,
                                  transmissible_torque)


@dataclass(frozen=True)
class WearReport:
    """Everything `benchlab wear` prints and plots, per sample and per engagement."""

    time: np.ndarray
    power_w: np.ndarray
    temperatures: pd.DataFrame  # the model's T_pressure_plate, T_flywheel, T_air (degC)
    measured_flywheel_c: np.ndarray
    history: WearHistory
    engagements: pd.DataFrame
    split: float
    spec: ClutchSpec
    health: Health
    life: LifeDistribution
    mu_estimate: np.ndarray | None
    mu_model: np.ndarray
    dt: float

    @property
    def friction_energy_j(self) -> float:
        return friction_energy(self.power_w, self.dt)

    def final_state(self) -> WearState:
        return self.history.final()

    def expected_at_horizon(self) -> dict[str, float]:
        """Mean wear state after the horizon's engagements under the run's load (expectation, not a percentile)."""
        mean = self.engagements[list(STATE_FIELDS)].mean().to_numpy() if len(self.engagements) else np.zeros(4)
        final = self.final_state()
        state = {name: getattr(final, name) + self.life.horizon_engagements * m for name, m in zip(STATE_FIELDS, mean)}
        state["transmissible_torque_Nm"] = float(transmissible_torque(self.spec, *state.values()))
        return state

    def side_summary(self, side: str) -> dict[str, float]:
        """Energy, wear in this run and in total, remaining height, μ loss and μ at the rating temperature."""
        final, start = self.final_state(), self.spec.initial
        column = "T_pressure_plate" if side == "plate" else "T_flywheel"
        share = self.split if side == "plate" else 1.0 - self.split
        weight = self.power_w / self.power_w.sum() if self.power_w.sum() > 0 else None
        temps = self.temperatures[column].to_numpy()
        rating = self.spec.rating_temperature_c
        force = normal_force(self.spec, total_wear_mm(self.spec, final.wear_plate_mm, final.wear_flywheel_mm), rating)
        return {"energy_J": share * self.friction_energy_j,
                "mean_lining_temperature_C": float(np.sum(weight * temps)) if weight is not None else None,
                "max_lining_temperature_C": float(np.max(temps)),
                "wear_run_mm": final.wear_mm(side) - start.wear_mm(side), "wear_total_mm": final.wear_mm(side),
                "height_mm": self.spec.height_mm - final.wear_mm(side), "friction_loss": final.loss(side),
                "mu_at_rating": float(friction_coefficient(self.spec, rating, 0.0, force, final.loss(side)))}

    def mu_summary(self) -> dict[str, float] | None:
        """Where the run has actuator position: μ estimated from measured torque beside the model's μ."""
        if self.mu_estimate is None or not np.isfinite(self.mu_estimate).any():
            return None
        ok = np.isfinite(self.mu_estimate)
        p10, p50, p90 = np.percentile(self.mu_estimate[ok], [10, 50, 90])
        return {"samples": int(ok.sum()), "p10": float(p10), "median": float(p50), "p90": float(p90),
                "model_median": float(np.median(self.mu_model[ok]))}

    def as_dict(self) -> dict[str, object]:
        """The `benchlab wear --json` object."""
        return {"friction_energy_J": self.friction_energy_j, "engagements": int(len(self.engagements)),
                "slip_time_s": float(self.engagements["slip_time_s"].sum()), "split": self.split,
                "clutch": self.spec.source,
                "wear": {side: self.side_summary(side) for side in SIDES},
                "health": self.health.as_dict(),
                "life": {**self.life.as_dict(), "expected_at_horizon": self.expected_at_horizon()},
                "mu_estimate": self.mu_summary(),
                "engagement_details": self.engagements.to_dict(orient="records")}


def analyse_wear(run: pd.DataFrame, params: ModelParams, spec: ClutchSpec | None = None,
                 horizon: int = DEFAULT_HORIZON, paths: int = DEFAULT_PATHS, seed: int = 0,
                 gap_s: float = DEFAULT_GAP_S, params_source: str = "<params>") -> WearReport:
    """Eq. (1)-(3) over a run: energy from measured torque and slip, ϑ_P/ϑ_F from the model, wear, health, life."""
    spec = spec or default_clutch()
    dt = float(run.attrs["dt"])
    split = heat_split(params, params_source)
    temps = lining_temperatures(run, params, split, params_source)
    t_plate, t_fly, t_air = (temps[c].to_numpy() for c in ("T_pressure_plate", "T_flywheel", "T_air"))
    power = run_friction_power(run)
    history = wear_history(spec, power, split, t_plate, t_fly, dt)
    spans = engagement_spans(power > 0, dt, gap_s)
    table = engagement_table(spans, dt, power, split, {"T_plate": t_plate, "T_flywheel": t_fly}, history.increments)
    final = history.final()
    life = remaining_life(spec, final, table[list(STATE_FIELDS)].to_numpy(), table["cycle_s"].to_numpy(),
                          horizon, paths, seed)
    cum = history.cumulative
    wear_total = total_wear_mm(spec, cum["wear_plate_mm"], cum["wear_flywheel_mm"])
    mu_est = estimate_mu(run, spec, power > 0, t_air, wear_total)
    position = held(run, ACTUATOR_CHANNEL) if ACTUATOR_CHANNEL in run.columns else None
    force = normal_force(spec, wear_total, t_air, position)
    slip = slip_rad_s(run)
    mu_model = 0.5 * (friction_coefficient(spec, t_plate, slip, force, cum["loss_plate"])
                      + friction_coefficient(spec, t_fly, slip, force, cum["loss_flywheel"]))
    return WearReport(time=run["time"].to_numpy(), power_w=power, temperatures=temps,
                      measured_flywheel_c=run["T_flywheel"].to_numpy(), history=history, engagements=table,
                      split=split, spec=spec, health=assess(spec, final), life=life, mu_estimate=mu_est,
                      mu_model=mu_model, dt=dt)
