"""The paper's clutch, eq. (6)-(11), written out in Python closures as benchlab defined it before model files:
the independent reference the model files are checked against (tests/test_model_file.py) and the peer their
speed is measured against (benchmarks/bench_model_file.py)."""

from __future__ import annotations

import numpy as np

from benchlab.network import Boundary, Link, Node, Source, ThermalNetwork


def python_clutch(nonlinear: bool) -> ThermalNetwork:
    """Pressure plate, flywheel, air, housing; R_PA = R_FA = eq. (11) (nonlinear) or R0; P split half and half."""
    def convection(p, ch):
        if not nonlinear:
            return p["R0"]
        clamped = ch["clutch_state"] >= 0.5
        exponent = np.where(clamped, p["b1"], p["b2"]) * ch["engine_speed"]
        return np.where(clamped, p["a1"], p["a2"]) * np.exp(exponent) + p["R0"]

    def half(p, ch):
        return 0.5 * ch["friction_power"]

    def engine(ch):
        return ch["T_engine"] if "T_engine" in ch and not np.all(np.isnan(ch["T_engine"])) else ch["T_ambient"]

    return ThermalNetwork(
        nodes=(Node("P", "C_P"), Node("F", "C_F"), Node("A", "C_A"), Node("T", "C_T")),
        boundaries=(Boundary("eng", engine), Boundary("amb", lambda ch: ch["T_ambient"])),
        links=(Link("P", "A", convection), Link("F", "A", convection), Link("A", "T", lambda p, ch: p["R_AT"]),
               Link("F", "eng", lambda p, ch: p["R_Feng"]), Link("T", "amb", lambda p, ch: p["R_Tamb"])),
        sources=(Source("P", half), Source("F", half)),
        outputs={"T_pressure_plate": "P", "T_flywheel": "F", "T_air": "A", "T_housing": "T"},
        initial={"P": "T_flywheel", "F": "T_flywheel", "A": "T_air", "T": "T_housing"},
        measured=("T_flywheel", "T_air", "T_housing"))
