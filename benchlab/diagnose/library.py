"""Physically named model extensions: each is an edit of the model file (its links, sources, nodes, lags and
parameter tables), so the extended model diagnose finds can be saved, simulated and re-identified.

A candidate names the signal the missing effect depends on and its mechanism (contract §3). The paper's
clutch gets its own library (convection laws, plate–flywheel conduction, heat split, radiation, …) where the
model has the clutch's nodes and links; any other network gets the generic one built from its structure
(a heat source driven by a signal into each node, a speed-dependent law on each link, an extra mass behind
each measured node, a lag on each sensor). The generic fallback learns a missing heat flow as a
piecewise-linear function of one signal, for effects no physical term describes.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from benchlab.model.catalog import builtin
from benchlab.model.definition import ModelDefinition, parse_model
from benchlab.network import Channels

STEFAN_BOLTZMANN = 5.670374419e-8
FALLBACK_KNOTS = 5
FALLBACK_RANGE = (0.005, 0.995)  # quantiles spanned by the knots: outliers do not stretch them
CLUTCH_NODES = ("P", "F", "A", "T")
CONVECTION_LINKS = ("R_PA", "R_FA")
SHARES = ("plate share", "flywheel share")
TEMPERATURE_UNIT = "degC"
SPEED_UNIT = "rpm"

Doc = dict


@dataclass(frozen=True)
class Candidate:
    """A proposed extension: what it depends on, how, and how to build the extended model."""

    key: str
    signal: str | None
    mechanism: str
    extension: str  # the formula, as the JSON shows it
    summary: str
    build: Callable[[ModelDefinition, Channels], ModelDefinition]
    physical: bool = True


def signal_values(name: str, ch: Channels) -> np.ndarray:
    """A candidate signal from the channels; `slip_speed` is |ω_e − ω_c| in rpm."""
    if name == "slip_speed":
        return np.abs(ch["engine_speed"] - ch["clutch_speed"])
    return ch[name]


def signal_expression(name: str) -> str:
    """The signal as a model-file expression."""
    return "abs(engine_speed - clutch_speed)" if name == "slip_speed" else name


def revise(model: ModelDefinition, key: str, edit: Callable[[Doc], None]) -> ModelDefinition:
    """The model file edited by `edit` (on its tables), named `<model>+<key>`, checked like any model file."""
    doc = model.to_doc()
    doc.setdefault("links", [])
    doc.setdefault("sources", [])
    doc.setdefault("lags", [])
    edit(doc)
    doc["name"] = f"{model.label}+{key}"
    doc["description"] = f"{model.description}; extended by diagnose: {key}" if model.description else key
    return parse_model(doc, model.source)


def _parameter(doc: Doc, name: str, start: float, low: float, high: float, unit: str = "",
               scale: float | None = None) -> None:
    doc["parameters"][name] = {"start": start, "min": low, "max": high, "unit": unit,
                               **({"scale": scale} if scale is not None else {})}


def _links(doc: Doc, names: tuple[str, ...]) -> list[dict]:
    return [l for l in doc["links"] if l["name"] in names]


def _wrap_links(names: tuple[str, ...], template: str) -> Callable[[Doc], None]:
    """Each named link's resistance r becomes template.format(r=r)."""
    def edit(doc: Doc) -> None:
        for link in _links(doc, names):
            link["resistance"] = template.format(r=link["resistance"])
    return edit


# --- the paper's clutch -------------------------------------------------------------------------------------

def engine_speed_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    """The convection law of the nonlinear clutch model file (eq. 11) in place of the constant R0."""
    nonlinear = builtin("nonlinear")
    law = next(l.resistance.text for l in nonlinear.links if l.name == CONVECTION_LINKS[1])

    def edit(doc: Doc) -> None:
        for link in _links(doc, CONVECTION_LINKS):
            link["resistance"] = re.sub(r"\bR0\b", f"({law})", link["resistance"])
        for name in ("a1", "b1", "a2", "b2"):
            doc["parameters"][name] = nonlinear.to_doc()["parameters"][name]
    return revise(model, "speed_convection", edit)


def state_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        _wrap_links(CONVECTION_LINKS, "({r}) * where(clutch_state >= 0.5, 1.0, k_open)")(doc)
        _parameter(doc, "k_open", 1.0, 0.2, 5.0, "1")
    return revise(model, "state_convection", edit)


def slip_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        _wrap_links(CONVECTION_LINKS, "({r}) / (1.0 + slip_gain * abs(engine_speed - clutch_speed) / 1000.0)")(doc)
        _parameter(doc, "slip_gain", 0.1, 1e-4, 20.0, "1 per 1000 rpm of slip")
    return revise(model, "slip_convection", edit)


def clamped_conduction(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        doc["links"].append({"name": "R_PF", "between": ["P", "F"],
                             "resistance": "where(clutch_state >= 0.5, R_PF, 1000000.0)"})
        _parameter(doc, "R_PF", 1.0, 1e-3, 1e3, "K/W")
    return revise(model, "clamped_conduction", edit)


def unequal_split(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        plate, flywheel = (next(s for s in doc["sources"] if s["name"] == name) for name in SHARES)
        plate["heat"], flywheel["heat"] = "split*friction_power", "(1 - split)*friction_power"
        _parameter(doc, "split", 0.5, 0.05, 0.95, "1 (plate share of P)", scale=0.5)
    return revise(model, "heat_split", edit)


def radiation(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    """Grey-body exchange linearised about the measured temperatures: ε·A·σ·4·T̄³ per kelvin of difference."""
    law = f"1 / (eps_area * {STEFAN_BOLTZMANN!r} * 4 * ((T_flywheel + T_housing) / 2 + 273.15) ** 3)"

    def edit(doc: Doc) -> None:
        doc["links"] += [{"name": "radiation F", "between": ["F", "T"], "resistance": law},
                         {"name": "radiation P", "between": ["P", "T"], "resistance": law}]
        _parameter(doc, "eps_area", 0.02, 1e-4, 2.0, "m2 (emissivity x area)")
    return revise(model, "radiation", edit)


# --- any network ---------------------------------------------------------------------------------------------

def channel_source(signal: str, node: str) -> Callable[[ModelDefinition, Channels], ModelDefinition]:
    """Heat q = k·(s/s_ref)^n into `node`, s a channel (engine or gearbox losses, iron losses, a heater)."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        ref = float(np.nanmax(np.abs(signal_values(signal, ch)))) or 1.0
        k, n = f"q_{signal}_{node}", f"n_{signal}_{node}"

        def edit(doc: Doc) -> None:
            doc["sources"].append({"name": f"{signal} source {node}", "node": node,
                                   "heat": f"{k} * (abs({signal_expression(signal)}) / {ref!r}) ** {n}"})
            _parameter(doc, k, 10.0, 1e-2, 1e4, "W (at the signal's maximum)")
            _parameter(doc, n, 1.0, 0.25, 4.0, "1 (exponent)")
        return revise(model, f"source_{signal}_{node}", edit)
    return build


def speed_link(link: str, signal: str) -> Callable[[ModelDefinition, Channels], ModelDefinition]:
    """The link's resistance falling with a speed (forced convection): R / (1 + g·|s|/s_ref)."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        ref = float(np.nanmax(np.abs(signal_values(signal, ch)))) or 1.0
        gain = f"g_{signal}_{re.sub(r'[^A-Za-z0-9_]', '_', link)}"

        def edit(doc: Doc) -> None:
            _wrap_links((link,), f"({{r}}) / (1.0 + {gain} * abs({signal}) / {ref!r})")(doc)
            _parameter(doc, gain, 0.1, 1e-4, 20.0, "1 (at the signal's maximum)")
        return revise(model, f"{signal}_link_{link}", edit)
    return build


def extra_mass(node: str, initial: str) -> Callable[[ModelDefinition, Channels], ModelDefinition]:
    """A thermal mass the model lacks, linked to `node`: stores and returns heat slowly."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        mass = "X" if node == "F" else f"X{node}"  # the clutch's flywheel hub keeps its name X
        capacity, resistance = f"C_{mass}", f"R_{node}{mass}"

        def edit(doc: Doc) -> None:
            doc["nodes"][mass] = capacity
            doc["links"].append({"name": resistance, "between": [node, mass], "resistance": resistance})
            doc.setdefault("initial", {})[mass] = initial
            _parameter(doc, capacity, 2000.0, 10.0, 1e5, "J/K")
            _parameter(doc, resistance, 0.1, 1e-3, 100.0, "K/W")
        return revise(model, "extra_mass" if node == "F" else f"extra_mass_{node}", edit)
    return build


def sensor_lag(output: str, node: str) -> Callable[[ModelDefinition, Channels], ModelDefinition]:
    """The sensor of `output` follows its node with a first-order lag."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tau = "tau_F" if output == "T_flywheel" else f"tau_{output}"

        def edit(doc: Doc) -> None:
            doc["lags"].append({"output": output, "node": node, "time_constant": tau})
            _parameter(doc, tau, 5.0, 0.05, 600.0, "s")
        return revise(model, "sensor_lag" if output == "T_flywheel" else f"sensor_lag_{output}", edit)
    return build


def piecewise_linear(signal: str, knots: np.ndarray, names: list[str]) -> str:
    """np.interp(signal, knots, values) as a model-file expression: flat beyond the outer knots."""
    s = signal_expression(signal)
    terms = [names[0]]
    for i in range(len(knots) - 1):
        lo, hi = float(knots[i]), float(knots[i + 1])
        terms.append(f"({names[i + 1]} - {names[i]}) * (minimum(maximum({s}, {lo!r}), {hi!r}) - {lo!r}) / {hi - lo!r}")
    return " + ".join(terms)


def fallback_source(signal: str, node: str) -> Callable[[ModelDefinition, Channels], ModelDefinition]:
    """A learned heat flow into `node`: piecewise linear in the signal, knots evenly spread over its range.

    Even spacing, not quantiles: a signal that is mostly zero (torque, power, slip) would put most
    quantile knots at zero and leave the range where the effect lives with one segment.
    """
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        low, high = np.nanquantile(signal_values(signal, ch), FALLBACK_RANGE)
        knots = np.unique(np.linspace(low, high, FALLBACK_KNOTS))
        names = [f"g_{signal}_{node}_{i}" for i in range(len(knots))]

        def edit(doc: Doc) -> None:
            doc["sources"].append({"name": f"learned {signal} {node}", "node": node,
                                   "heat": piecewise_linear(signal, knots, names)})
            for name in names:
                _parameter(doc, name, 0.0, -500.0, 500.0, "W (at the knot)", scale=10.0)
        return revise(model, f"learned_{signal}_{node}", edit)
    return build


SOURCE_SIGNALS = ("engine_speed", "clutch_speed")
FALLBACK_SIGNALS = ("engine_speed", "slip_speed", "clutch_speed", "clutch_torque", "clutch_state",
                    "friction_power", "load_torque", "T_flywheel")


def _available(signal: str | None, channels: Channels) -> bool:
    """Whether the runs hold the signal a candidate depends on."""
    if signal is None:
        return True
    if signal == "slip_speed":
        return "engine_speed" in channels and "clutch_speed" in channels
    return signal in channels


def is_clutch(model: ModelDefinition) -> bool:
    """Whether the model has the paper's clutch structure the clutch library edits (nodes, convection links, shares)."""
    return (set(CLUTCH_NODES) <= set(model.nodes) and set(CONVECTION_LINKS) <= {l.name for l in model.links}
            and set(SHARES) <= {s.name for s in model.sources})


def clutch_candidates(model: ModelDefinition) -> list[Candidate]:
    """The clutch's library: physical extensions first, then the generic fallbacks."""
    out = []
    if "a1" not in model.parameters:
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
                  "a thermal mass the model lacks stores and returns heat slowly", extra_mass("F", "T_flywheel")),
        Candidate("sensor_lag", "T_flywheel", "sensor", "T_flywheel measured = first-order lag tau_F of the flywheel",
                  "the flywheel sensor lags the flywheel temperature", sensor_lag("T_flywheel", "F")),
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
            out.append(Candidate(f"learned_{signal}_{node}", signal, "other",
                                 f"learned heat flow into {where} = g({signal}), piecewise linear",
                                 f"a heat flow into the {where} that depends on {signal}; no physical term fits it",
                                 fallback_source(signal, node), physical=False))
    return out


def network_candidates(model: ModelDefinition, signals: list[str], units: Mapping[str, str]) -> list[Candidate]:
    """The library of any network, from its structure: sources per signal and node, speed laws per link, an extra
    mass behind each measured node, a lag per sensor; then learned heat flows per signal and node."""
    measured_nodes = list(dict.fromkeys(model.outputs.values()))
    lagged = {g.output for g in model.lags}
    out = []
    for signal in signals:
        for node in model.nodes:
            out.append(Candidate(f"source_{signal}_{node}", signal, "heat_source", f"heat into {node} = q*({signal}/max)^n",
                                 f"a heat source driven by {signal} warms node {node}", channel_source(signal, node)))
    for signal in (s for s in signals if units.get(s) == SPEED_UNIT):
        for link in model.links:
            out.append(Candidate(f"{signal}_link_{link.name}", signal, "convection",
                                 f"{link.name} = R / (1 + g*|{signal}|/max)",
                                 f"heat crosses {link.name} faster at higher {signal}: convection grows with it",
                                 speed_link(link.name, signal)))
    for node in measured_nodes:
        channel = next(c for c, n in model.outputs.items() if n == node)
        out.append(Candidate(f"extra_mass_{node}", None, "capacity", f"extra node X{node} linked to {node}",
                             f"a thermal mass the model lacks stores and returns heat behind node {node}",
                             extra_mass(node, channel)))
    for output, node in model.outputs.items():
        if output not in lagged:
            out.append(Candidate(f"sensor_lag_{output}", output, "sensor", f"{output} measured = first-order lag of {node}",
                                 f"the {output} sensor lags its node's temperature", sensor_lag(output, node)))
    for signal in signals:
        for node in model.nodes:
            out.append(Candidate(f"learned_{signal}_{node}", signal, "other", f"learned heat flow into {node} = g({signal})",
                                 f"a heat flow into node {node} that depends on {signal}; no physical term fits it",
                                 fallback_source(signal, node), physical=False))
    return out


def network_signals(model: ModelDefinition, channels: Channels, units: Mapping[str, str]) -> list[str]:
    """The signals a missing effect of a network may depend on: the inputs its laws read (speeds, currents,
    powers; not temperatures, which are its states and boundaries), where the runs hold them and they vary.
    A model names the inputs that matter on its bench; every other channel of a run would multiply the fits."""
    return [c for c in sorted(model.law_channels()) if c in channels and units.get(c) != TEMPERATURE_UNIT
            and np.nanmax(channels[c]) > np.nanmin(channels[c])]


def candidates(model: ModelDefinition, channels: Channels, units: Mapping[str, str] | None = None) -> list[Candidate]:
    """The library for this model, none on a channel the runs lack (`load_torque` is optional in a run file)."""
    units = dict(units or {})
    found = (clutch_candidates(model) if is_clutch(model)
             else network_candidates(model, network_signals(model, channels, units), units))
    return [c for c in found if _available(c.signal, channels)]
