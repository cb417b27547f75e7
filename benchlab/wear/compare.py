"""Why temperature matters: one run's wear with the model's, a constant and the bench's true lining temperatures."""

from __future__ import annotations

import numpy as np
import pandas as pd

from benchlab.model.params import ModelParams
from benchlab.wear.clutchfile import ClutchSpec, default_clutch
from benchlab.wear.energy import run_friction_power
from benchlab.wear.model import wear_history
from benchlab.wear.state import WearState
from benchlab.wear.thermal import heat_split, lining_temperatures


def temperature_sensitivity(run: pd.DataFrame, params: ModelParams, spec: ClutchSpec | None = None,
                            constant_c: float | None = None,
                            temperatures: pd.DataFrame | None = None) -> dict[str, dict[str, float]]:
    """This run's wear per side under three temperature sources; `error_pct`: mean |side error| against the truth.

    "model": ϑ_P, ϑ_F simulated from the run; "constant": one temperature for both sides (default the
    run's mean measured chamber air, what one has without a model); "true": the simulated bench's own
    states (`run.attrs["true_states"]`, keys "P" and "F"), present only for simulated runs.
    `temperatures` reuses the model's lining temperatures of an earlier `analyse_wear` of the same run.
    """
    spec = spec or default_clutch()
    dt, split = float(run.attrs["dt"]), heat_split(params)
    power = run_friction_power(run)
    temps = lining_temperatures(run, params, split) if temperatures is None else temperatures
    constant = float(np.nanmean(run["T_air"])) if constant_c is None else float(constant_c)
    sources = {"model": (temps["T_pressure_plate"].to_numpy(), temps["T_flywheel"].to_numpy()),
               "constant": (np.full(len(run), constant), np.full(len(run), constant))}
    truth = run.attrs.get("true_states")
    if truth is not None:
        sources["true"] = (np.asarray(truth["P"]), np.asarray(truth["F"]))
    out: dict[str, dict[str, float]] = {}
    for name, (plate, flywheel) in sources.items():
        final = wear_history(spec, power, split, plate, flywheel, dt, WearState()).final()
        out[name] = {"wear_plate_mm": final.wear_plate_mm, "wear_flywheel_mm": final.wear_flywheel_mm,
                     "loss_plate": final.loss_plate, "loss_flywheel": final.loss_flywheel}
    if "true" in out:
        for name, result in out.items():
            errors = [(result[k] - out["true"][k]) / out["true"][k] for k in ("wear_plate_mm", "wear_flywheel_mm")]
            result["error_pct"] = 100.0 * float(np.mean(np.abs(errors)))
    out["constant"]["temperature_C"] = constant
    return out
