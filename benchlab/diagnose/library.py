"""Physically named model extensions: each is an edit of the thermal network plus its new parameters.

A candidate names the signal the missing effect depends on and its mechanism (contract §3).
The generic fallback learns a missing heat flow as a piecewise-linear function of one signal,
for effects no physical term describes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from benchlab.identify.spec import CONVECTION_FREE, ModelSpec, ParamSpec
from benchlab.network import Channels, Lag, Link, Node, Params, Source, ThermalNetwork

STEFAN_BOLTZMANN = 5.670374419e-8
FALLBACK_KNOTS = 5
FALLBACK_RANGE = (0.005, 0.995)  # quantiles spanned by the knots: outliers do not stretch them


@dataclass(frozen=True)
class Candidate:
    """A proposed extension: what it depends on, how, and how to build the extended spec."""

    key: str
    signal: str | None
    mechanism: str
    extension: str  # the formula, as the JSON shows it
    summary: str
    build: Callable[[ModelSpec, Channels], ModelSpec]
    physical: bool = True


def signal_values(name: str, ch: Channels) -> np.ndarray:
    """A candidate signal from the channels; `slip_speed` is |ω_e − ω_c| in rpm."""
    if name == "slip_speed":
        return np.abs(ch["engine_speed"] - ch["clutch_speed"])
    if name == "time":
        return ch["time"]
    return ch[name]


def _convection_links(net: ThermalNetwork, law) -> ThermalNetwork:
    return net.replace_links(lambda l: l.label not in ("R_PA", "R_FA"),
                             (Link("P", "A", law, "R_PA"), Link("F", "A", law, "R_FA")))


def _current_convection(spec: ModelSpec):
    return next(l.resistance for l in spec.network.links if l.label == "R_FA")


def engine_speed_convection(spec: ModelSpec, ch: Channels) -> ModelSpec:
    free = tuple(p for p in CONVECTION_FREE if p.name not in {q.name for q in spec.free})
    fixed = {k: v for k, v in spec.fixed.items() if k not in {p.name for p in free}}
    return ModelSpec(spec.name + "+speed_convection", spec.network, spec.free + free, fixed)


def state_convection(spec: ModelSpec, ch: Channels) -> ModelSpec:
    base = _current_convection(spec)

    def law(p: Params, c: Channels):
        return base(p, c) * np.where(c["clutch_state"] >= 0.5, 1.0, p["k_open"])
    return spec.extended(spec.name + "+state_convection", _convection_links(spec.network, law),
                         (ParamSpec("k_open", 1.0, 0.2, 5.0),))


def slip_convection(spec: ModelSpec, ch: Channels) -> ModelSpec:
    base = _current_convection(spec)

    def law(p: Params, c: Channels):
        return base(p, c) / (1.0 + p["slip_gain"] * signal_values("slip_speed", c) / 1000.0)
    return spec.extended(spec.name + "+slip_convection", _convection_links(spec.network, law),
                         (ParamSpec("slip_gain", 0.1, 1e-4, 20.0),))


def clamped_conduction(spec: ModelSpec, ch: Channels) -> ModelSpec:
    net = spec.network.with_link(Link("P", "F", lambda p, c: np.where(c["clutch_state"] >= 0.5, p["R_PF"], 1e6),
                                      "R_PF"))
    return spec.extended(spec.name + "+clamped_conduction", net, (ParamSpec("R_PF", 1.0, 1e-3, 1e3),))


def unequal_split(spec: ModelSpec, ch: Channels) -> ModelSpec:
    kept = tuple(s for s in spec.network.sources if s.label not in ("P/2 plate", "P/2 flywheel"))
    sources = (Source("P", lambda p, c: p["split"] * c["friction_power"], "plate share"),
               Source("F", lambda p, c: (1 - p["split"]) * c["friction_power"], "flywheel share")) + kept
    net = ThermalNetwork(spec.network.nodes, spec.network.boundaries, spec.network.links, sources,
                         spec.network.outputs, spec.network.lags, spec.network.initial)
    return spec.extended(spec.name + "+heat_split", net, (ParamSpec("split", 0.5, 0.05, 0.95, log=False),))


def channel_source(signal: str, node: str) -> Callable[[ModelSpec, Channels], ModelSpec]:
    """Heat q = k·(s/s_ref)^n into `node`, s a channel (engine or gearbox losses, a heater)."""
    def build(spec: ModelSpec, ch: Channels) -> ModelSpec:
        ref = float(np.nanmax(np.abs(signal_values(signal, ch)))) or 1.0
        kname, nname = f"q_{signal}_{node}", f"n_{signal}_{node}"

        def flow(p: Params, c: Channels):
            return p[kname] * (np.abs(signal_values(signal, c)) / ref) ** p[nname]
        net = spec.network.with_source(Source(node, flow, f"{signal} source"))
        return spec.extended(f"{spec.name}+source_{signal}_{node}", net,
                             (ParamSpec(kname, 10.0, 1e-2, 1e4), ParamSpec(nname, 1.0, 0.25, 4.0)))
    return build


def extra_mass(spec: ModelSpec, ch: Channels) -> ModelSpec:
    net = spec.network.with_node(Node("X", "C_X"), "T_flywheel").with_link(
        Link("F", "X", lambda p, c: p["R_FX"], "R_FX"))
    return spec.extended(spec.name + "+extra_mass", net,
                         (ParamSpec("C_X", 2000.0, 10.0, 1e5), ParamSpec("R_FX", 0.1, 1e-3, 100.0)))


def sensor_lag(spec: ModelSpec, ch: Channels) -> ModelSpec:
    net = spec.network.with_lag(Lag("F_meas", "F", "tau_F"), "T_flywheel")
    return spec.extended(spec.name + "+sensor_lag", net, (ParamSpec("tau_F", 5.0, 0.05, 600.0),))


def radiation(spec: ModelSpec, ch: Channels) -> ModelSpec:
    """Grey-body exchange linearised about the measured temperatures: ε·A·σ·4·T̄³ per kelvin of difference."""
    def law(p: Params, c: Channels):
        mean_k = np.round(c["T_flywheel_filled"] + c["T_housing_filled"]) / 2 + 273.15  # 0.5 K steps
        return 1.0 / (p["eps_area"] * STEFAN_BOLTZMANN * 4 * mean_k ** 3)
    net = spec.network.with_link(Link("F", "T", law, "radiation F")).with_link(Link("P", "T", law, "radiation P"))
    return spec.extended(spec.name + "+radiation", net, (ParamSpec("eps_area", 0.02, 1e-4, 2.0),))


def fallback_source(signal: str, node: str) -> Callable[[ModelSpec, Channels], ModelSpec]:
    """A learned heat flow into `node`: piecewise linear in the signal, knots evenly spread over its range.

    Even spacing, not quantiles: a signal that is mostly zero (torque, power, slip) would put most
    quantile knots at zero and leave the range where the effect lives with one segment.
    """
    def build(spec: ModelSpec, ch: Channels) -> ModelSpec:
        low, high = np.nanquantile(signal_values(signal, ch), FALLBACK_RANGE)
        knots = np.unique(np.linspace(low, high, FALLBACK_KNOTS))
        names = [f"g_{signal}_{node}_{i}" for i in range(len(knots))]

        def flow(p: Params, c: Channels):
            return np.interp(signal_values(signal, c), knots, [p[n] for n in names])
        net = spec.network.with_source(Source(node, flow, f"learned {signal}"))
        extra = tuple(ParamSpec(n, 0.0, -500.0, 500.0, log=False, scale=10.0) for n in names)
        return spec.extended(f"{spec.name}+learned_{signal}_{node}", net, extra)
    return build


SOURCE_SIGNALS = ("engine_speed", "clutch_speed")
FALLBACK_SIGNALS = ("engine_speed", "slip_speed", "clutch_speed", "clutch_torque", "clutch_state",
                    "friction_power", "load_torque", "T_flywheel_filled")


def _available(signal: str | None, channels: Channels) -> bool:
    """Whether the runs hold the signal a candidate depends on."""
    if signal is None:
        return True
    if signal == "slip_speed":
        return "engine_speed" in channels and "clutch_speed" in channels
    return signal in channels or f"{signal}_filled" in channels


def candidates(baseline_is_linear: bool, channels: Channels) -> list[Candidate]:
    """The library: physical extensions first, then the generic fallbacks; none on a channel the runs lack
    (`load_torque` is optional in a run file)."""
    out = []
    if baseline_is_linear:
        out.append(Candidate("speed_convection", "engine_speed", "convection", "R_FA = R_PA = a*exp(b*engine_speed) + R0",
                             "cool-down rate depends on engine speed: convection grows with engine speed",
                             engine_speed_convection))
    out += [
        Candidate("state_convection", "clutch_state", "convection", "R_FA = R_PA = f_R * (k_open if S = 0)",
                  "convection differs between clamped and open clutch", state_convection),
        Candidate("slip_convection", "slip_speed", "convection", "R_FA = R_PA = f_R / (1 + g*|slip_speed|/1000)",
                  "heat leaves faster while slipping: convection grows with slip speed", slip_convection),
        Candidate("clamped_conduction", "clutch_state", "conduction", "R_PF between plate and flywheel when S = 1",
                  "plate and flywheel exchange heat through the clamped disc", clamped_conduction),
        Candidate("heat_split", "friction_power", "heat_split", "P_plate = s*P, P_flywheel = (1-s)*P",
                  "friction heat is not split half and half between plate and flywheel", unequal_split),
        Candidate("extra_mass", None, "capacity", "extra node X: C_X linked to the flywheel by R_FX",
                  "a thermal mass the model lacks stores and returns heat slowly", extra_mass),
        Candidate("sensor_lag", "T_flywheel", "sensor", "T_flywheel measured = first-order lag tau_F of the flywheel",
                  "the flywheel sensor lags the flywheel temperature", sensor_lag),
        Candidate("radiation", "T_flywheel", "other", "radiation eps_A*sigma*(T_F^4 - T_T^4) from plate and flywheel",
                  "hot plate and flywheel lose heat by radiation to the housing", radiation),
    ]
    for signal in SOURCE_SIGNALS:
        for node, where in (("F", "flywheel"), ("T", "housing")):
            out.append(Candidate(f"source_{signal}_{node}", signal, "heat_source",
                                 f"heat into {where} = q*({signal}/max)^n",
                                 f"a heat source driven by {signal} warms the {where}", channel_source(signal, node)))
    for signal in FALLBACK_SIGNALS:
        for node, where in (("F", "flywheel"), ("A", "air")):
            name = signal.removesuffix("_filled")
            out.append(Candidate(f"learned_{name}_{node}", name, "other",
                                 f"learned heat flow into {where} = g({name}), piecewise linear",
                                 f"a heat flow into the {where} that depends on {name}; no physical term fits it",
                                 fallback_source(signal, node), physical=False))
    return [c for c in out if _available(c.signal, channels)]
