"""Hidden effects diagnose was never built around: laws no candidate of its library has, in places it never looked.

The effects of `sim_bench.plant` were written together with diagnose's library, so finding them again tests
the search but not whether its forms are right. These sit elsewhere (a node bridging the unmeasured plate and
the air, a new state-dependent path to the housing, the air sensor, a heat source into the plate, a loss that is
a product of two signals) and follow laws chosen for their physics, not for a candidate (issue 18). Each says,
besides the signal and mechanism `Effect` declares, which other signals it depends on (a finding naming any of
them names the right cause) and which nodes it touches.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from benchlab.network import Lag, Link, Node, Source
from sim_bench.plant import Effect

OPEN_CIRCUIT_K_PER_W = 1e6  # a path that is not there: no heat crosses it


@dataclass(frozen=True)
class Hidden:
    """A hidden effect and what naming it right means: a mechanism of `mechanism`, with a signal among
    `signals` (None: depends on no channel), sitting at one of `nodes`."""

    effect: Effect
    signals: tuple[str | None, ...]
    nodes: tuple[str, ...] = ()

    @classmethod
    def declared(cls, effect: Effect) -> "Hidden":
        """An effect of `sim_bench.plant`, named right by the one signal and mechanism it declares."""
        return cls(effect, (effect.signal,))

    @property
    def mechanism(self) -> str:
        return self.effect.mechanism

    def named(self, signal: str | None, mechanism: str) -> bool:
        """Whether a finding (signal, mechanism) names this effect's cause."""
        return mechanism == self.mechanism and signal in self.signals


def plate_cover(capacity_j_per_k: float, plate_k_per_w: float = 0.3, air_k_per_w: float = 0.3) -> Hidden:
    """A clutch cover: a mass of `capacity_j_per_k` J/K bridging the pressure plate (`plate_k_per_w` K/W, through the
    diaphragm spring and rivets) and the chamber air (`air_k_per_w` K/W). Nothing measures it or the plate."""
    def edit(net, p):
        return (net.with_node(Node("K", "C_K"), "T_air")
                .with_link(Link("P", "K", lambda q, ch: q["R_PK"], "R_PK"))
                .with_link(Link("K", "A", lambda q, ch: q["R_KA"], "R_KA")))
    effect = Effect("plate_cover", None, "capacity", edit,
                    {"C_K": capacity_j_per_k, "R_PK": plate_k_per_w, "R_KA": air_k_per_w})
    return Hidden(effect, (None,), ("P", "A"))


def release_bearing_heat(watts: float, speed_scale_rpm: float = 1000.0) -> Hidden:
    """The release bearing, pressed on the diaphragm spring while the clutch is open (S = 0), heats the pressure
    plate with its drag: q = `watts`·tanh(ω_e / `speed_scale_rpm`) W, saturating in engine speed; none when clamped."""
    def heat(q, ch):
        return q["bearing_w"] * (ch["clutch_state"] < 0.5) * np.tanh(np.abs(ch["engine_speed"]) / q["bearing_rpm"])

    def edit(net, p):
        return net.with_source(Source("P", heat, "release bearing"))
    effect = Effect("release_bearing_heat", "clutch_state", "heat_source", edit,
                    {"bearing_w": watts, "bearing_rpm": speed_scale_rpm})
    return Hidden(effect, ("clutch_state", "engine_speed"), ("P",))


def release_path_conduction(resistance_k_per_w: float) -> Hidden:
    """While the clutch is open the release bearing and fork touch the diaphragm spring: heat flows from the
    pressure plate to the housing through `resistance_k_per_w` K/W; no path while clamped."""
    def law(q, ch):
        return np.where(ch["clutch_state"] < 0.5, q["R_PT"], OPEN_CIRCUIT_K_PER_W)

    def edit(net, p):
        return net.with_link(Link("P", "T", law, "R_PT"))
    effect = Effect("release_path_conduction", "clutch_state", "conduction", edit, {"R_PT": resistance_k_per_w})
    return Hidden(effect, ("clutch_state",), ("P", "T"))


def air_sensor_lag(time_constant_s: float) -> Hidden:
    """The chamber-air PT1000 sits in a thermowell: it follows the air with a first-order lag of
    `time_constant_s` s."""
    def edit(net, p):
        return net.with_lag(Lag("A_sensor", "A", "tau_A"), "T_air")
    effect = Effect("air_sensor_lag", "T_air", "sensor", edit, {"tau_A": time_constant_s})
    return Hidden(effect, ("T_air",), ("A",))


def gear_mesh_loss(watts_at_reference: float) -> Hidden:
    """Gear-mesh losses heat the housing in proportion to transmitted power, load torque times input-shaft speed:
    q = `watts_at_reference`·(|T_load| / 300 N·m)·(ω_c / 2000 rpm) W, a product of two signals."""
    def heat(q, ch):
        return q["mesh_w"] * (np.abs(ch["load_torque"]) / 300.0) * (np.abs(ch["clutch_speed"]) / 2000.0)

    def edit(net, p):
        return net.with_source(Source("T", heat, "gear mesh"))
    effect = Effect("gear_mesh_loss", "clutch_speed", "heat_source", edit, {"mesh_w": watts_at_reference})
    return Hidden(effect, ("clutch_speed", "load_torque"), ("T",))


def slip_dependent_split(low_share: float, high_share: float, slip_scale_rpm: float = 800.0) -> Hidden:
    """The friction heat's split between pressure plate and flywheel shifts with slip speed (the contact pattern and
    the flash temperatures move with sliding speed): plate share low + (high − low)·tanh(|ω_e − ω_c| / scale), the
    flywheel the rest. Heat is moved between the two, never made: the sum stays the friction power."""
    def share(q, ch):
        slip = np.abs(ch["engine_speed"] - ch["clutch_speed"])
        return q["share_low"] + (q["share_high"] - q["share_low"]) * np.tanh(slip / slip_scale_rpm)

    def edit(net, p):
        kept = tuple(s for s in net.sources if s.label not in ("plate share", "flywheel share"))
        return replace(net, sources=(Source("P", lambda q, ch: share(q, ch) * ch["friction_power"], "plate share"),
                                     Source("F", lambda q, ch: (1 - share(q, ch)) * ch["friction_power"],
                                            "flywheel share")) + kept)
    effect = Effect("slip_dependent_split", "slip_speed", "heat_split", edit,
                    {"share_low": low_share, "share_high": high_share})
    return Hidden(effect, ("slip_speed", "engine_speed", "clutch_speed", "friction_power"), ("P", "F"))
