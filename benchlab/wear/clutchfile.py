"""Clutch files (TOML): the constants z, r and the characteristic maps of eq. (1)-(3), checked on load.

The defaults (`default_clutch`, mirrored in examples/clutch.toml) are assumptions for a passenger-car
single-plate dry clutch with organic linings; docs/wear.md gives their sources.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.errors import InputError, read_document
from benchlab.values import check_keys, finite_number
from benchlab.wear.maps import Map1D, make_map
from benchlab.wear.state import WearState

#: Map name -> (axis key, value key, required). Optional maps default to a factor of 1.
MAPS: dict[str, tuple[str, str, bool]] = {
    "friction": ("temperature_C", "mu", True),
    "friction_slip": ("slip_rad_s", "factor", False),
    "friction_force": ("force_N", "factor", False),
    "spring": ("wear_mm", "force_N", True),
    "spring_temperature": ("temperature_C", "factor", False),
    "actuator": ("position_mm", "factor", False),
    "wear_rate": ("temperature_C", "mm3_per_J", True),
    "friction_loss": ("temperature_C", "per_MJ", True),
}
#: Required scalars: (section, key) -> what is expected.
SCALARS: dict[tuple[str, str], str] = {
    ("clutch", "friction_faces"): "an even integer >= 2 (z)",
    ("clutch", "mean_radius_m"): "a positive number (r, m)",
    ("clutch", "max_engine_torque_Nm"): "a positive number (T_e,max, N*m)",
    ("clutch", "rating_temperature_C"): "a number (lining temperature for the health check, degC)",
    ("lining", "area_per_face_mm2"): "a positive number (mm^2)",
    ("lining", "height_mm"): "a positive number (new lining height per face, mm)",
    ("lining", "min_height_mm"): "a number >= 0 below height_mm (wear limit per face, mm)",
}
STATE_KEYS = ("wear_plate_mm", "wear_flywheel_mm", "loss_plate", "loss_flywheel")

DEFAULT_DOC: dict[str, Any] = {
    "clutch": {"friction_faces": 2, "mean_radius_m": 0.1, "max_engine_torque_Nm": 180.0,
               "rating_temperature_C": 100.0},
    "lining": {"area_per_face_mm2": 25100.0, "height_mm": 3.5, "min_height_mm": 2.5},
    "state": {"wear_plate_mm": 0.0, "wear_flywheel_mm": 0.0, "loss_plate": 0.0, "loss_flywheel": 0.0},
    "maps": {
        "friction": {"temperature_C": [20.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0],
                     "mu": [0.30, 0.30, 0.29, 0.26, 0.22, 0.18, 0.15]},
        "friction_slip": {"slip_rad_s": [0.0, 50.0, 150.0, 300.0], "factor": [1.0, 0.98, 0.95, 0.92]},
        "friction_force": {"force_N": [500.0, 4000.0, 8000.0], "factor": [1.03, 1.0, 0.98]},
        "spring": {"wear_mm": [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0],
                   "force_N": [4000.0, 4200.0, 4250.0, 4100.0, 3700.0, 3100.0, 2300.0]},
        "spring_temperature": {"temperature_C": [20.0, 100.0, 200.0, 300.0], "factor": [1.0, 0.985, 0.96, 0.93]},
        "actuator": {"position_mm": [0.0, 2.0, 4.0, 6.0, 8.0], "factor": [1.0, 0.85, 0.55, 0.2, 0.0]},
        "wear_rate": {"temperature_C": [20.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0],
                      "mm3_per_J": [3.0e-5, 3.5e-5, 4.5e-5, 7.0e-5, 1.4e-4, 2.8e-4, 5.6e-4]},
        "friction_loss": {"temperature_C": [20.0, 150.0, 200.0, 250.0, 300.0, 350.0],
                          "per_MJ": [5.0e-5, 5.0e-5, 0.002, 0.01, 0.04, 0.1]},
    },
}


@dataclass(frozen=True)
class ClutchSpec:
    """Constants and maps of one clutch; `initial` is the wear it already has when the run starts."""

    faces: int
    mean_radius_m: float
    max_engine_torque_nm: float
    rating_temperature_c: float
    area_mm2: float
    height_mm: float
    min_height_mm: float
    maps: dict[str, Map1D]
    initial: WearState
    source: str

    @property
    def faces_per_side(self) -> int:
        """Faces rubbing on each side (pressure plate / flywheel): z/2."""
        return self.faces // 2


def _scalar(doc: dict[str, Any], source: str, section: str, key: str) -> float:
    table = doc.get(section)
    field, expected = f"{section}.{key}", SCALARS[(section, key)]
    if not isinstance(table, dict) or key not in table:
        raise InputError(source, field, f"{expected} (missing)")
    value = table[key]
    if finite_number(value) is None:
        raise InputError(source, field, f"{expected}, got {value!r}")
    positive = "positive" in expected or key == "friction_faces"
    if (positive and value <= 0) or (key == "min_height_mm" and value < 0):
        raise InputError(source, field, f"{expected}, got {value!r}")
    if key == "friction_faces" and (value != int(value) or int(value) % 2):
        raise InputError(source, field, f"{expected}, got {value!r}")
    return float(value)


def _map(doc: dict[str, Any], source: str, name: str) -> Map1D:
    axis_key, value_key, required = MAPS[name]
    table = doc.get("maps", {}).get(name) if isinstance(doc.get("maps"), dict) else None
    field = f"maps.{name}"
    if table is None and not required:
        return Map1D(np.array([0.0, 1.0]), np.array([1.0, 1.0]))
    if not isinstance(table, dict):
        raise InputError(source, field, f"a table with {axis_key} and {value_key} (missing)")
    for key in (axis_key, value_key):
        if key not in table:
            raise InputError(source, f"{field}.{key}", "a list of numbers (missing)")
    return make_map(source, field, axis_key, value_key, table[axis_key], table[value_key], minimum=0.0)


def _state(doc: dict[str, Any], source: str) -> WearState:
    table = doc.get("state", {})
    if not isinstance(table, dict):
        raise InputError(source, "state", "a table of the wear already accumulated")
    values = {}
    for key in STATE_KEYS:
        value = table.get(key, 0.0)
        upper = 1.0 if key.startswith("loss") else math.inf
        number = finite_number(value)
        if number is None or not 0.0 <= number < upper:
            raise InputError(source, f"state.{key}", f"a number in [0, {upper}), got {value!r}")
        values[key] = number
    return WearState(**values)


def _check_known_keys(doc: dict[str, Any], source: str) -> None:
    """Every table holds only the keys this format defines: a misspelt key (`wear_plat_mm`) is refused, not left at
    its default (the wear already accumulated would read as zero)."""
    sections = {section for section, _ in SCALARS}
    check_keys(source, "", doc, (*sections, "state", "maps"))
    for section in sections:
        if isinstance(doc.get(section), dict):
            check_keys(source, section, doc[section], [key for s, key in SCALARS if s == section])
    if isinstance(doc.get("state"), dict):
        check_keys(source, "state", doc["state"], STATE_KEYS)
    maps = doc.get("maps")
    if isinstance(maps, dict):
        check_keys(source, "maps", maps, MAPS)
        for name, table in maps.items():
            if isinstance(table, dict):
                check_keys(source, f"maps.{name}", table, MAPS[name][:2])


def clutch_from_doc(doc: dict[str, Any], source: str) -> ClutchSpec:
    """Build and check a ClutchSpec from a parsed TOML document."""
    _check_known_keys(doc, source)
    values = {key: _scalar(doc, source, section, key) for section, key in SCALARS}
    if values["min_height_mm"] >= values["height_mm"]:
        raise InputError(source, "lining.min_height_mm", f"less than lining.height_mm ({values['height_mm']})")
    return ClutchSpec(
        faces=int(values["friction_faces"]), mean_radius_m=values["mean_radius_m"],
        max_engine_torque_nm=values["max_engine_torque_Nm"], rating_temperature_c=values["rating_temperature_C"],
        area_mm2=values["area_per_face_mm2"], height_mm=values["height_mm"], min_height_mm=values["min_height_mm"],
        maps={name: _map(doc, source, name) for name in MAPS}, initial=_state(doc, source), source=source)


def load_clutch(path: "str | os.PathLike[str]") -> ClutchSpec:
    """Read a clutch TOML file; InputError names the file and the field on any defect."""
    path = Path(path)
    doc = read_document(path, "clutch file", tomllib.loads, (tomllib.TOMLDecodeError,), "TOML")
    return clutch_from_doc(doc, str(path))


def default_clutch() -> ClutchSpec:
    """The documented default clutch (same values as examples/clutch.toml)."""
    return clutch_from_doc(DEFAULT_DOC, "<default clutch>")
