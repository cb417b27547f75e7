"""The reference clutch: a passenger-car single-plate dry clutch written from geometry and handbook physics.

Not the paper's network: eleven states (two friction-ring annuli and the bulk of the flywheel, crankshaft end, clutch
disc, pressure plate, cover with diaphragm spring, chamber air, bell housing, gearbox case, two PT1000s with their own
lag), contact conduction through the lining only while clamped, rotating-disc forced convection from the engine speed
(the disc: its own speed), natural convection and radiation from the plant's own temperatures, heat into the crankshaft,
friction heat split by thermal effusivity and by radius, and μ(ϑ) of the lining scaling the torque the clutch
transmits. Every number and its source: docs/plant.md. It runs on the same network engine (benchlab.network) as the
paper's plant; the laws that read temperatures are solved by fixed-point iteration (ThermalPlant).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from benchlab.jit import njit

from benchlab.network import Boundary, Lag, Link, Node, Source, ThermalNetwork
from sim_bench.plant import KELVIN, STEFAN_BOLTZMANN, ThermalPlant

# -- geometry (m) and materials (SI): docs/plant.md gives the source of each -----------------------------------
R_IN, R_MID, R_OUT = 0.075, 0.095, 0.120  # friction annulus of a 240 mm clutch; sensors at 85 mm and 108 mm
RING_THICKNESS = 0.012  # flywheel cast iron under the friction face that heats within a launch
LINING_THICKNESS = 0.0035  # per side
GAP_OPEN = 0.001  # air gap per side with the clutch open
CAST_IRON = {"rho": 7200.0, "c": 460.0, "k": 50.0}  # grey iron EN-GJL-250
STEEL = {"c": 470.0}
ALUMINIUM = {"c": 900.0}
LINING = {"rho": 2000.0, "c": 1000.0, "k": 0.5}  # organic (resin-bonded) friction material
AIR = {"k": 0.028, "nu": 1.8e-5, "rho": 1.1, "c": 1007.0}  # at about 50 degC
FRICTION_CONTACT_H = 2000.0  # W/m²K, clamped lining on cast iron


def _annulus(r1: float, r2: float) -> float:
    return math.pi * (r2 ** 2 - r1 ** 2)


AREA_INNER, AREA_OUTER = _annulus(R_IN, R_MID), _annulus(R_MID, R_OUT)
AREA_FACE = AREA_INNER + AREA_OUTER


def _effusivity(m: Mapping[str, float]) -> float:
    return math.sqrt(m["k"] * m["rho"] * m["c"])


#: share of each interface's friction heat that goes into the metal side (Blok/Charron partition by effusivity)
METAL_SHARE = _effusivity(CAST_IRON) / (_effusivity(CAST_IRON) + _effusivity(LINING))
#: share of the flywheel face's heat in the inner annulus: uniform pressure, power density ∝ r (∫ r² dr)
INNER_SHARE = (R_MID ** 3 - R_IN ** 3) / (R_OUT ** 3 - R_IN ** 3)


def _lining_r(area: float) -> float:
    """Clamped: half the lining stack's conduction plus the contact, over `area` (K/W)."""
    return LINING_THICKNESS / (LINING["k"] * area) + 1.0 / (FRICTION_CONTACT_H * area)


def _gap_r(area: float) -> float:
    """Open: conduction across the air gap (K/W)."""
    return GAP_OPEN / (AIR["k"] * area)


def reference_params() -> dict[str, float]:
    """Capacities (J/K), resistances (K/W), areas (m²), emissivity-areas (m²) and the friction law of the reference
    clutch, derived from the geometry and materials above (docs/plant.md)."""
    ring_c = CAST_IRON["rho"] * CAST_IRON["c"] * RING_THICKNESS
    ring_conduction = CAST_IRON["k"] * 2 * math.pi * R_MID * RING_THICKNESS / ((R_OUT - R_IN) / 2)
    return {
        # capacities
        "C_ring_inner": ring_c * AREA_INNER, "C_ring_outer": ring_c * AREA_OUTER,
        "C_flywheel_bulk": (9.0 - CAST_IRON["rho"] * RING_THICKNESS * AREA_FACE) * CAST_IRON["c"],  # 9 kg flywheel
        "C_crank": 2.5 * STEEL["c"], "C_disc": LINING["rho"] * 2 * LINING_THICKNESS * AREA_FACE * LINING["c"]
        + 0.3 * STEEL["c"], "C_plate": 3.2 * CAST_IRON["c"], "C_cover": 1.85 * STEEL["c"],
        "C_air": 0.006 * AIR["rho"] * AIR["c"], "C_bell": 5.0 * ALUMINIUM["c"],
        "C_gearbox": 25.0 * ALUMINIUM["c"] + 1.7 * 1900.0,  # case and 2 l of gear oil
        # conduction
        "R_ring": 1.0 / ring_conduction,
        "R_inner_bulk": 0.015 / (CAST_IRON["k"] * AREA_INNER), "R_outer_bulk": 0.015 / (CAST_IRON["k"] * AREA_OUTER),
        "R_bulk_crank": 1.0 / (3000.0 * 0.0035), "R_crank_engine": 1.0,
        "R_plate_disc": _lining_r(AREA_FACE), "R_inner_disc": _lining_r(AREA_INNER),
        "R_outer_disc": _lining_r(AREA_OUTER), "R_plate_disc_open": _gap_r(AREA_FACE),
        "R_inner_disc_open": _gap_r(AREA_INNER), "R_outer_disc_open": _gap_r(AREA_OUTER),
        "R_plate_cover": 1.5, "R_cover_bulk": 0.8, "R_bell_gearbox": 0.15,
        # convecting areas (m²): to the chamber air, and the housing's outside
        "A_bulk": 0.08, "A_plate": 0.03, "A_cover": 0.09, "A_bell_in": 0.15, "A_bell_out": 0.30,
        "A_gearbox_out": 0.70,
        "vent_l_per_s_per_krpm": 0.5, "vent_leak_l_per_s": 0.1,
        # radiation: effective emissivity × area (m²) to the housing, and of the housing to the room
        "eA_bulk": 0.18 * 0.08, "eA_plate": 0.18 * 0.03, "eA_cover": 0.136 * 0.09,
        "eA_bell_out": 0.3 * 0.30, "eA_gearbox_out": 0.3 * 0.70,
        # sensors: PT1000 in a bore behind the friction face
        "tau_sensor_inner": 3.0, "tau_sensor_outer": 4.0,
        "tau_sensor_air": 20.0,  # the wired PT1000 in the housing's opening: a sheathed probe in moving air
        # friction: μ(ϑ)/μ(ϑ_cal) = 1 + mu_slope (ϑ - ϑ_cal), the controllers calibrated at ϑ_cal
        "mu_slope_per_k": -1.0e-3, "mu_cal_c": 40.0,
    }


# -- laws ---------------------------------------------------------------------------------------------------------
# Each law that reads a speed or a temperature is one compiled loop over its samples (numpy's dozen small array
# operations per law cost 15-40 µs on a 2 s chunk of the bench, several times per chunk), which reuses the previous
# sample's value where the inputs repeat it (a speed held, the first pass's held temperatures), and its bin where the
# resistance falls well inside that bin (`_binned_after`: no log, no exp; the bin the log gives, bit for bit). The formulas are
# numpy's, in the same order, on each sample; only the last bit of an exp, log or power may differ from numpy's
# vectorised ones, and it does not reach the solver, which keys each 0.5 % bin (tests/test_reference_plant.py
# compares the plant with states stored from the numpy laws).
_BIN = 0.005  # laws are evaluated to 0.5 % (far below their own uncertainty) so the solver sees few operating points
_R_OUT_SQUARED, _AIR_NU, _AIR_K, _AIR_RHO, _AIR_C = R_OUT ** 2, AIR["nu"], AIR["k"], AIR["rho"], AIR["c"]


@njit(cache=True, nogil=True)
def _binned(r: float) -> float:  # pragma: no cover - compiled
    return math.exp(np.rint(math.log(r) / _BIN) * _BIN)


# a bin's value times these: its edges, pulled in by 1e-9 (a million times exp's and log's rounding), so that a
# resistance between them is in that bin whatever log(r) rounds to
_INSIDE_LOW, _INSIDE_HIGH = math.exp(-_BIN / 2) * (1 + 1e-9), math.exp(_BIN / 2) * (1 - 1e-9)


@njit(cache=True, nogil=True)
def _inside(r: float, value: float) -> bool:  # pragma: no cover - compiled
    """Whether `r` is, clear of the edges, in the bin whose value is `value`: its bin without a log."""
    return value * _INSIDE_LOW < r < value * _INSIDE_HIGH


@njit(cache=True, nogil=True)
def _binned_after(r: float, k: int, out: np.ndarray) -> float:  # pragma: no cover - compiled
    """`_binned(r)` for sample k of a law's loop: the sample before's value where r lies inside its bin."""
    return out[k - 1] if k > 0 and _inside(r, out[k - 1]) else _binned(r)


@njit(cache=True, nogil=True)
def rotating_h(rpm: float) -> float:  # pragma: no cover - compiled
    """Mean heat-transfer coefficient (W/m²K) of a disc of radius R_OUT rotating at `rpm` in air: Cobb & Saunders,
    laminar Nu = 0.36 Re^0.5, turbulent Nu = 0.015 Re^0.8, the larger of the two (Re = ω r²/ν): bolts, cover windows
    and spring fingers trip the boundary layer, so the turbulent law holds from well below the smooth disc's Re 2.4e5."""
    re = abs(rpm) * math.pi / 30.0 * _R_OUT_SQUARED / _AIR_NU
    nu = max(0.36 * math.sqrt(re), 0.015 * re ** 0.8)
    return nu * _AIR_K / R_OUT


@njit(cache=True, nogil=True)
def natural_h(difference_k: float, length_m: float) -> float:  # pragma: no cover - compiled
    """Laminar natural convection of a vertical surface in air, h = 1.42 (ΔT/L)^0.25 (W/m²K), ΔT at least 0.5 K."""
    return 1.42 * (max(abs(difference_k), 0.5) / length_m) ** 0.25


@njit(cache=True, nogil=True)
def radiation_h(eps_area: float, hot: float, cold: float) -> float:  # pragma: no cover - compiled
    """Linearised radiation conductance εAσ(T1² + T2²)(T1 + T2) (W/K) between two temperatures (degC)."""
    t1, t2 = hot + KELVIN, cold + KELVIN
    return eps_area * STEFAN_BOLTZMANN * (t1 ** 2 + t2 ** 2) * (t1 + t2)


@njit(cache=True, nogil=True)
def _convection_r(rpm, node_c, air_c, wall_c, area, eps_area, length):  # pragma: no cover - compiled
    """Forced (engine speed) + natural (own ΔT to the air) + radiation to the housing wall, as one resistance per
    sample (the chamber air is transparent: radiation goes to the wall, which the air follows closely)."""
    out = np.empty(rpm.shape[0])
    forced = 0.0
    for k in range(rpm.shape[0]):
        if k > 0 and node_c[k] == node_c[k - 1] and air_c[k] == air_c[k - 1] and wall_c[k] == wall_c[k - 1] \
                and rpm[k] == rpm[k - 1]:
            out[k] = out[k - 1]
            continue
        if k == 0 or rpm[k] != rpm[k - 1]:
            forced = rotating_h(rpm[k])
        g = (forced + natural_h(node_c[k] - air_c[k], length)) * area
        out[k] = _binned_after(1.0 / (g + radiation_h(eps_area, node_c[k], wall_c[k])), k, out)
    return out


@njit(cache=True, nogil=True)
def _open_face_r(speed, clutch_state, area):  # pragma: no cover - compiled
    """A friction face to the chamber air per sample: 1e6 K/W while clamped, else the rotating face with a still-air
    floor of 3 W/m²K (a face in a 1 mm gap)."""
    out = np.empty(speed.shape[0])
    for k in range(speed.shape[0]):
        if k > 0 and speed[k] == speed[k - 1] and clutch_state[k] == clutch_state[k - 1]:
            out[k] = out[k - 1]
            continue
        out[k] = _binned(1e6 if clutch_state[k] >= 0.5 else 1.0 / ((rotating_h(speed[k]) + 3.0) * area))
    return out


@njit(cache=True, nogil=True)
def _air_housing_r(rpm, air_c, wall_c, area):  # pragma: no cover - compiled
    """Chamber air to the bell housing's inside per sample: half the disc's forced convection plus natural."""
    out = np.empty(rpm.shape[0])
    forced = 0.0
    for k in range(rpm.shape[0]):
        if k > 0 and air_c[k] == air_c[k - 1] and wall_c[k] == wall_c[k - 1] and rpm[k] == rpm[k - 1]:
            out[k] = out[k - 1]
            continue
        if k == 0 or rpm[k] != rpm[k - 1]:
            forced = rotating_h(rpm[k])
        out[k] = _binned_after(1.0 / ((0.5 * forced + natural_h(air_c[k] - wall_c[k], 0.3)) * area), k, out)
    return out


@njit(cache=True, nogil=True)
def _ventilation_r(rpm, leak_l_per_s, l_per_s_per_krpm):  # pragma: no cover - compiled
    """Air exchanged through the vent openings, pumped by the rotating clutch, as a resistance per sample."""
    out = np.empty(rpm.shape[0])
    for k in range(rpm.shape[0]):
        if k > 0 and rpm[k] == rpm[k - 1]:
            out[k] = out[k - 1]
            continue
        litres = leak_l_per_s + l_per_s_per_krpm * abs(rpm[k]) / 1000.0
        out[k] = _binned(1.0 / (litres * 1e-3 * _AIR_RHO * _AIR_C))
    return out


@njit(cache=True, nogil=True)
def _outside_r(node_c, ambient_c, area, eps_area, length):  # pragma: no cover - compiled
    """A housing's outside to the room per sample: natural convection plus radiation."""
    out = np.empty(node_c.shape[0])
    for k in range(node_c.shape[0]):
        if k > 0 and node_c[k] == node_c[k - 1] and ambient_c[k] == ambient_c[k - 1]:
            out[k] = out[k - 1]
            continue
        g = natural_h(node_c[k] - ambient_c[k], length) * area
        out[k] = _binned_after(1.0 / (g + radiation_h(eps_area, node_c[k], ambient_c[k])), k, out)
    return out


def _state(ch: Mapping[str, np.ndarray], node: str) -> np.ndarray:
    return ch[f"_state_{node}"]


def _convection(node: str, area: str, eps_area: str, length: float = 0.24):
    """Engine-side part to chamber air, from the previous iterate's temperatures."""
    def law(p, ch):
        return _convection_r(ch["engine_speed"], _state(ch, node), _state(ch, "A"), _state(ch, "T"), p[area],
                             p[eps_area], length)
    return law


def _open_face(area: float, speed: str):
    """A friction face exposed to the chamber air only while the clutch is open."""
    def law(p, ch):
        return _open_face_r(ch[speed], ch["clutch_state"], area)
    return law


def _clamped(closed: str, open_: str):
    def law(p, ch):
        return np.where(ch["clutch_state"] >= 0.5, p[closed], p[open_])
    return law


def _air_housing(p, ch):
    return _air_housing_r(ch["engine_speed"], _state(ch, "A"), _state(ch, "T"), p["A_bell_in"])


def _ventilation(p, ch):
    return _ventilation_r(ch["engine_speed"], p["vent_leak_l_per_s"], p["vent_l_per_s_per_krpm"])


def _outside(node: str, area: str, eps_area: str, length: float):
    def law(p, ch):
        return _outside_r(_state(ch, node), ch["T_ambient"], p[area], p[eps_area], length)
    return law


def _constant(name: str):
    return lambda p, ch: p[name]


def _engine(ch: Mapping[str, np.ndarray]) -> np.ndarray:
    return ch["T_engine"] if "T_engine" in ch else ch["T_ambient"]


#: state -> the channel its truth is recorded as (/truth); the sensors' lags read T_flywheel_1 and _2
CHANNEL_NAMES = {"P": "T_pressure_plate", "F": "T_flywheel", "Fi": "T_flywheel_inner", "B": "T_flywheel_bulk",
                 "K": "T_crankshaft", "L": "T_clutch_disc", "D": "T_cover", "A": "T_chamber_air", "T": "T_housing",
                 "G": "T_gearbox", "S1": "T_flywheel_1", "S2": "T_flywheel_2", "SA": "T_air"}


def reference_network() -> ThermalNetwork:
    """Nodes, links, heat sources, sensor lags of the reference clutch; F is the outer friction annulus (most of
    the face's heat), Fi the inner one, B the flywheel's bulk on the crankshaft end K."""
    nodes = (Node("F", "C_ring_outer"), Node("Fi", "C_ring_inner"), Node("B", "C_flywheel_bulk"),
             Node("K", "C_crank"), Node("L", "C_disc"), Node("P", "C_plate"), Node("D", "C_cover"),
             Node("A", "C_air"), Node("T", "C_bell"), Node("G", "C_gearbox"))
    boundaries = (Boundary("eng", _engine), Boundary("amb", lambda ch: ch["T_ambient"]))
    links = (
        Link("F", "Fi", _constant("R_ring"), "ring radial"),
        Link("F", "B", _constant("R_outer_bulk"), "outer ring to bulk"),
        Link("Fi", "B", _constant("R_inner_bulk"), "inner ring to bulk"),
        Link("B", "K", _constant("R_bulk_crank"), "flywheel bolts to crank flange"),
        Link("K", "eng", _constant("R_crank_engine"), "crankshaft into the engine"),
        Link("P", "L", _clamped("R_plate_disc", "R_plate_disc_open"), "plate through lining"),
        Link("F", "L", _clamped("R_outer_disc", "R_outer_disc_open"), "outer ring through lining"),
        Link("Fi", "L", _clamped("R_inner_disc", "R_inner_disc_open"), "inner ring through lining"),
        Link("P", "D", _constant("R_plate_cover"), "plate to diaphragm fulcrum and straps"),
        Link("D", "B", _constant("R_cover_bulk"), "cover bolted to flywheel rim"),
        Link("B", "A", _convection("B", "A_bulk", "eA_bulk"), "flywheel bulk to air"),
        Link("P", "A", _convection("P", "A_plate", "eA_plate"), "plate back to air"),
        Link("D", "A", _convection("D", "A_cover", "eA_cover"), "cover and spring to air"),
        Link("P", "A", _open_face(AREA_FACE, "engine_speed"), "plate face to air (open)"),
        Link("F", "A", _open_face(AREA_OUTER, "engine_speed"), "outer face to air (open)"),
        Link("Fi", "A", _open_face(AREA_INNER, "engine_speed"), "inner face to air (open)"),
        Link("L", "A", _open_face(2 * AREA_FACE, "clutch_speed"), "disc faces to air (open)"),
        Link("A", "T", _air_housing, "air to bell housing"),
        Link("A", "amb", _ventilation, "ventilation"),
        Link("T", "G", _constant("R_bell_gearbox"), "bell housing to gearbox case"),
        Link("T", "amb", _outside("T", "A_bell_out", "eA_bell_out", 0.3), "bell housing outside"),
        Link("G", "amb", _outside("G", "A_gearbox_out", "eA_gearbox_out", 0.4), "gearbox case outside"),
    )
    share = {"P": 0.5 * METAL_SHARE, "F": 0.5 * METAL_SHARE * (1 - INNER_SHARE), "Fi": 0.5 * METAL_SHARE * INNER_SHARE,
             "L": 1 - METAL_SHARE}
    sources = tuple(Source(node, lambda q, ch, f=f: f * ch["friction_power"], f"friction heat {node}")
                    for node, f in share.items())
    lags = (Lag("S1", "Fi", "tau_sensor_inner"), Lag("S2", "F", "tau_sensor_outer"), Lag("SA", "A", "tau_sensor_air"))
    outputs = {CHANNEL_NAMES[s]: s for s in ("S1", "S2", "SA", "T", "P", "F", "Fi", "B", "K", "L", "D", "A", "G")}
    initial = {s: "T_flywheel" for s in ("F", "Fi", "B", "K", "L", "P", "D", "S1", "S2")}
    initial.update(A="T_air", SA="T_air", T="T_housing", G="T_housing")
    return ThermalNetwork(nodes, boundaries, links, sources, outputs, lags, initial)


def friction_factor(params: Mapping[str, float], disc_c: float) -> float:
    """μ(ϑ_disc)/μ(ϑ_cal): the torque the clutch transmits per newton-metre the controller commands (its actuator
    is calibrated at ϑ_cal), μ(ϑ) linear in the disc temperature, kept within 0.5 .. 1.2."""
    return float(np.clip(1.0 + params["mu_slope_per_k"] * (disc_c - params["mu_cal_c"]), 0.5, 1.2))


def reference_plant() -> ThermalPlant:
    """The simulated bench's default plant: the reference clutch, temperatures of its laws solved by iteration."""
    params = reference_params()
    return ThermalPlant(params, network=reference_network(), reads_states=True,
                        friction=lambda state: friction_factor(params, state["L"]), name="reference")


#: the plants a simulated bench can be asked for by name (`--plant`): the reference clutch (default), the paper's network
PLANTS = {"reference": reference_plant, "paper": ThermalPlant}
DEFAULT_PLANT = "reference"


def plant_named(name: str) -> ThermalPlant:
    """A fresh plant of the given name (one of PLANTS)."""
    return PLANTS[name]()
