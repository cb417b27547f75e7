"""The paper's dry clutch as a thermal network (eq. 6-9) with the convection law of eq. (10)-(11)."""

from __future__ import annotations

import numpy as np

from benchlab.network import Boundary, Channels, Link, Node, Params, Source, ThermalNetwork

CAPACITIES = ("C_P", "C_F", "C_A", "C_T")
RESISTANCES = ("R_AT", "R_Feng", "R_Tamb", "R0")
CONVECTION = ("a1", "b1", "a2", "b2")
LINEAR_PARAMS = CAPACITIES + RESISTANCES
NONLINEAR_PARAMS = LINEAR_PARAMS + CONVECTION

#: Simulated channel name -> network state, in the order of the contract's /simulated group.
SIMULATED_CHANNELS = {"T_pressure_plate": "P", "T_flywheel": "F", "T_air": "A", "T_housing": "T"}
#: Measured channels the model predicts (contract section 5).
PREDICTED_CHANNELS = ("T_flywheel", "T_air", "T_housing")


def engine_temperature(channels: Channels) -> np.ndarray:
    """ϑ_eng: the measured engine temperature where present, else ambient (paper, section IV)."""
    if "T_engine" in channels and not np.all(np.isnan(channels["T_engine"])):
        return channels["T_engine"]
    return channels["T_ambient"]


def convection_resistance(params: Params, channels: Channels) -> "float | np.ndarray":
    """R_FA = R_PA = f_R(ω_e, S), eq. (11); the constant R0 when a1 = a2 = 0 (linear model)."""
    a1, a2 = params.get("a1", 0.0), params.get("a2", 0.0)
    if a1 == 0.0 and a2 == 0.0:
        return params["R0"]
    speed = channels["engine_speed"]
    clamped = channels["clutch_state"] >= 0.5
    exponent = np.where(clamped, params.get("b1", 0.0), params.get("b2", 0.0)) * speed
    return np.where(clamped, a1, a2) * np.exp(exponent) + params["R0"]


def _half_power(params: Params, channels: Channels) -> np.ndarray:
    return 0.5 * channels["friction_power"]


def _constant(name: str):
    return lambda params, channels: params[name]


def clutch_network() -> ThermalNetwork:
    """Pressure plate P, flywheel F, chamber air A, housing T; boundaries engine and ambient."""
    return ThermalNetwork(
        nodes=(Node("P", "C_P"), Node("F", "C_F"), Node("A", "C_A"), Node("T", "C_T")),
        boundaries=(Boundary("eng", engine_temperature), Boundary("amb", lambda ch: ch["T_ambient"])),
        links=(
            Link("P", "A", convection_resistance, "R_PA"),
            Link("F", "A", convection_resistance, "R_FA"),
            Link("A", "T", _constant("R_AT"), "R_AT"),
            Link("F", "eng", _constant("R_Feng"), "R_Feng"),
            Link("T", "amb", _constant("R_Tamb"), "R_Tamb"),
        ),
        sources=(Source("P", _half_power, "P/2 plate"), Source("F", _half_power, "P/2 flywheel")),
        outputs={"T_flywheel": "F", "T_air": "A", "T_housing": "T", "T_pressure_plate": "P"},
        initial={"P": "T_flywheel", "F": "T_flywheel", "A": "T_air", "T": "T_housing"},
    )
