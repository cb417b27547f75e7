"""Model extensions generated from the model's structure, each an edit of the model file (its links, sources,
nodes, lags and parameter tables), so the extended model diagnose finds can be saved, simulated and re-identified.

The generator works on any network (benchlab.model.ModelDefinition): every link group (links sharing one
resistance law) × every varying signal but the heat input (path_signals) under three resistance laws (linear,
power, exponential in the signal; one factor for an on/off signal); every node × signal as a heat source; a new
link between each pair of nodes that have none; one extra node hung on each node and one bridging each pair of
nodes; each measured node's capacity as a linear law of its own temperature; a first-order lag, an offset-and-gain
calibration and a drift on each measured output; heat moved between each pair of sources; then, last, learned
piecewise-linear heat flows. Every candidate starts NESTED: at its start
values it is its parent model (a factor of one, a source of zero watts, a node of 1 J/K, a link of 1e4 K/W, a lag
of 5 ms, a sensor of gain 1, offset 0 K and drift 0 K/s, a capacity that does not change with temperature), and that point lies inside its bounds, so a fit that
starts there can only lower the parent's cost.
The paper's clutch gets the same generator plus physical names (convection on R_PA/R_FA, conduction on R_Feng,
`heat_split` of plate and flywheel shares, `extra_mass` behind the flywheel, `sensor_lag` of the flywheel),
the convection law of eq. (11) where the baseline lacks it, the clamped plate–flywheel conduction and radiation.
A candidate names the signal the missing effect depends on and its mechanism (contract §3).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from benchlab.identify.data import SLIP_POWER
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
#: Nested starts: a node this small (J/K) is no node, a link this large (K/W) is no link, a lag this short (s) no lag.
NESTED_CAPACITY = 1.0
NESTED_RESISTANCE = 1.0e4
NESTED_LAG_S = 0.005
OPEN_CIRCUIT = 1.0e6  # K/W of a gated link while it is open: no heat crosses
#: A signal link's screening starts, times the typical resistance: where the signal is small most of the time (a
#: torque), the link's conductance at the signal's maximum is far from the model's typical one
COMPOSED_PROBES = (0.1, 1.0, 10.0)
MIN_SHARE = 1.0e-6  # a signal link's conductance share where its signal is zero: R / 1e-6, no heat crosses
EXPONENT_RANGE = (0.05, 8.0)  # of a signal in a law or a source: from nearly a step (x^0.05) to a steep rise
#: A calibration candidate's bounds: a sensor's gain within ±20 % and its offset within ±20 K (a PT1000 class B is
#: ±0.3 K + 0.5 % at 100 °C; a wrong curve or a wrong lead resistance, some kelvin)
CALIBRATION_GAIN = (0.8, 1.25)
CALIBRATION_OFFSET_K = 20.0
CALIBRATION_KEY = "sensor_calibration_"  # + the output's channel
DRIFT_KEY = "sensor_drift_"  # + the output's channel
CAPACITY_KEY = "capacity_level_"  # + the channel that measures the node
#: A capacity law's bounds keep it at least this share of its parameter over the runs' temperatures (k up to
#: (1 − share)/the largest distance from its reference); below it, on runs beyond them, it is held there
CAPACITY_FLOOR = 0.1
#: A drift candidate's bound (K/s): 36 K an hour either way
CALIBRATION_DRIFT_K_PER_S = 0.01
#: Screening starts of a sensor lag (s): a lag of 5 ms is flat to first order, so its screen starts also here
LAG_PROBES_S = (1.0, 10.0, 100.0)
LAWS = ("linear", "power", "exponential")  # a link's resistance against a signal; an on/off signal gets one factor
#: The clutch's signals a missing effect may depend on (where the runs hold them and they vary).
CLUTCH_SIGNALS = ("engine_speed", "clutch_speed", "slip_speed", "clutch_state", "clutch_torque", "friction_power",
                  "load_torque")

Doc = dict
Build = Callable[[ModelDefinition, Channels], ModelDefinition]


def path_signals(signals: list[str]) -> list[str]:
    """The signals a link's conductance may follow: all but the heat input (SLIP_POWER). A conductance follows its
    path's state (contact pressure, air flow, temperature), and heat input changes that only through temperatures,
    which the |ΔT| and level laws read; its factors, clutch torque and slip speed, are signals of their own. A law
    of the heat input on a path drains heat in proportion to it and mimics effects that are no path: a flywheel
    capacity rising with its temperature (two 45-55 min runs) was named a crankshaft conduction growing 54x with
    friction power, then a |ΔT| law on the same link (1.28x the floor, both causes); without it, beyond the library."""
    return [s for s in signals if s != SLIP_POWER]


@dataclass(frozen=True)
class Candidate:
    """A proposed extension: what it depends on, how, where it acts, and how to build the extended model.

    `structural`: its effect is not first order at the nested start (a node of 1 J/K is, to first order, more
    capacity on its neighbour), so the screen fits it whatever its score.
    """

    key: str
    signal: str | None
    mechanism: str
    extension: str  # the formula, as the JSON shows it
    summary: str
    build: Build
    physical: bool = True
    nodes: tuple[str, ...] = ()  # the nodes it changes (where a sensor would see it first)
    structural: bool = False
    #: further screening starts from the current values (an extra node of a tenth or all of its neighbour's
    #: capacity): a structural candidate's nested start is flat, and the screen keeps the best of all its starts
    probes: Callable[[Mapping[str, float]], list[dict[str, float]]] | None = None
    #: parameters with no first-order effect at the nested start (an exponent while its factor is zero): the score
    #: test skips their columns, which are zero there
    inert: tuple[str, ...] = ()
    #: at its nested start the extension is exactly its parent (a zero factor, not a link of 1e4 K/W): the score
    #: test takes the parent's residuals instead of simulating it once more
    exact: bool = True
    #: every signal the extension reads (a product of two reads both; `signal` names the first)
    signals: tuple[str, ...] = ()
    #: parameters the extension fits once per run group instead of once for all runs (per_group_candidates): the
    #: model stays as it is, the runs disagree
    splits: tuple[str, ...] = ()
    #: two steps of the library in one (composed_links): screened in slots of their own, so that they never crowd
    #: the one-step candidates out of the screen
    composed: bool = False
    #: the link it adds between two nodes (its resistance's name): once a candidate adding it is accepted, the others
    #: that would add it again no longer apply
    adds_link: str | None = None
    #: its screening starts keep it its parent exactly (a switch's factor at 0, its thresholds placed): each is scored
    #: as a nested start, one column
    nested_probes: bool = False
    #: starts near its best-scored screening start, scored after the grid (a switch's threshold between the quantiles
    #: beside it: its cost jumps as samples cross the threshold, so the grid's spacing alone would decide what is found)
    refine: Callable[[Mapping[str, float]], list[dict[str, float]]] | None = None
    #: keys of its simpler forms that the rule on nodes and signals does not find (a switch's latch: the same law
    #: with its band beyond the runs): screened beside it, and taken in its place where its own parameters are not identified
    simpler: tuple[str, ...] = ()

    @property
    def reads(self) -> tuple[str, ...]:
        """Every signal the extension depends on."""
        return self.signals or ((self.signal,) if self.signal else ())


DIFFERENCE = "dT:"  # a derived signal |a − b| of two measured temperatures: "dT:T_flywheel-T_air"


def difference_signal(first: str, second: str) -> str:
    """The name of the derived signal |first − second| (a temperature difference across a link)."""
    return f"{DIFFERENCE}{first}-{second}"


def difference_channels(name: str) -> tuple[str, str]:
    """The two channels of a temperature difference signal."""
    first, second = name.removeprefix(DIFFERENCE).split("-")
    return first, second


def signal_values(name: str, ch: Channels) -> np.ndarray:
    """A candidate signal from the channels; `slip_speed` is |ω_e − ω_c| in rpm, a `dT:a-b` signal |a − b| in K."""
    if name == "slip_speed":
        return np.abs(ch["engine_speed"] - ch["clutch_speed"])
    if name.startswith(DIFFERENCE):
        first, second = difference_channels(name)
        return np.abs(ch[first] - ch[second])
    return ch[name]


def signal_expression(name: str) -> str:
    """The signal as a model-file expression."""
    if name.startswith(DIFFERENCE):
        return "abs({} - {})".format(*difference_channels(name))
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


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", text)


def _reference(signal: str, ch: Channels) -> float:
    """The signal's largest magnitude in the runs: laws read |s| / reference, between 0 and 1."""
    return float(np.nanmax(np.abs(signal_values(signal, ch)))) or 1.0


def is_on_off(signal: str, ch: Channels) -> bool:
    """Whether the signal takes two values at most (the clutch state): one factor, not a law, describes it."""
    return len(np.unique(signal_values(signal, ch)[np.isfinite(signal_values(signal, ch))])) <= 2


def gated(signal: str, ch: Channels, on: bool, value: str, otherwise: str) -> str:
    """`value` while an on/off signal is on (at its higher value; `on` False: while off), else `otherwise`."""
    values = np.unique(signal_values(signal, ch)[np.isfinite(signal_values(signal, ch))])
    middle = float(values.mean()) if len(values) else 0.5
    first, second = (value, otherwise) if on else (otherwise, value)
    return f"where({signal_expression(signal)} >= {middle!r}, {first}, {second})"


def gate_expression(signal: str, ch: Channels, on: bool) -> str:
    """1 while an on/off signal is on, else 0; or the other way round."""
    return gated(signal, ch, on, "1.0", "0.0")


def factor_expression(signal: str, ch: Channels, exponent: str, gate: bool | None = None) -> str:
    """A signal as a source factor: an on/off signal as its gate (on or off), any other as (|s|/max)^n."""
    if gate is not None:
        return gate_expression(signal, ch, gate)
    return f"(abs({signal_expression(signal)}) / {_reference(signal, ch)!r}) ** {exponent}"


# --- generated from the structure ------------------------------------------------------------------------------

def link_law(links: tuple[str, ...], signal: str, law: str) -> Build:
    """The links' resistance R against a signal, nested at R: linear R/(1 + g·x), power R/(1 + g·x^n),
    exponential R·(1 − g + g·exp(−k·x)) with x = |s|/max; an on/off signal: R·(1 + g·s)."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tag = f"{_slug(signal)}_{_slug(links[0])}"
        g = f"g_{law}_{tag}"
        if is_on_off(signal, ch):
            template, extra = f"({{r}}) * (1.0 + {g} * {signal_expression(signal)})", {}
        else:
            x = f"abs({signal_expression(signal)}) / {_reference(signal, ch)!r}"
            if law == "linear":
                template, extra = f"({{r}}) / (1.0 + {g} * {x})", {}
            elif law == "power":
                template, extra = f"({{r}}) / (1.0 + {g} * ({x}) ** n_{tag})", {f"n_{tag}": (2.0, EXPONENT_RANGE[0], EXPONENT_RANGE[1], "1 (exponent)")}
            else:
                template, extra = (f"({{r}}) * (1.0 - {g} + {g} * exp(-k_{tag} * {x}))",
                                   {f"k_{tag}": (3.0, 0.1, 30.0, "1 (rate over the signal's range)")})

        def edit(doc: Doc) -> None:
            _wrap_links(links, template)(doc)
            low = -0.9 if law != "exponential" else -5.0
            high = 1e3 if law != "exponential" else 0.95
            _parameter(doc, g, 0.0, low, high, "1 (factor on the conductance)", scale=0.5)
            for name, (start, lo, hi, unit) in extra.items():
                _parameter(doc, name, start, lo, hi, unit)
        return revise(model, f"{signal}_{law}_{links[0]}", edit)
    return build


def source_name(signals: tuple[str, ...], node: str, gates: tuple[bool | None, ...]) -> str:
    """The key of a heat source into `node` that reads `signals` (an on/off one while on or off)."""
    parts = [f"{_slug(s)}" + ("" if g is None else ("_on" if g else "_off")) for s, g in zip(signals, gates)]
    return f"source_{'_'.join(parts)}_{node}"


def channel_source(signals: tuple[str, ...], node: str, gates: tuple[bool | None, ...]) -> Build:
    """Heat q·Π factor(s) into `node`, q from 0 W: a continuous signal as (|s|/max)^n, an on/off one as its gate
    (while on or while off). One signal: engine or gearbox losses, a heater; two: a loss in proportion to a
    torque times a speed, or a drag only while the clutch is open."""
    key = source_name(signals, node, gates)

    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tag = key.removeprefix("source_")
        k = f"q_{tag}"
        exponents = [f"n{i + 1 if len(signals) > 1 else ''}_{tag}" for i in range(len(signals))]
        heat = " * ".join([k] + [factor_expression(s, ch, n, g) for s, n, g in zip(signals, exponents, gates)])

        def edit(doc: Doc) -> None:
            doc["sources"].append({"name": key, "node": node, "heat": heat})
            at = "W (at the signal's maximum)" if len(signals) == 1 else "W (at the signals' maxima)"
            _parameter(doc, k, 0.0, -1e4, 1e4, at, scale=10.0)
            for n, g in zip(exponents, gates):
                if g is None:
                    _parameter(doc, n, 1.0, EXPONENT_RANGE[0], EXPONENT_RANGE[1], "1 (exponent)")
        return revise(model, key, edit)
    return build


def source_exponents(signals: tuple[str, ...], node: str, gates: tuple[bool | None, ...]) -> tuple[str, ...]:
    """The exponents of channel_source: inert while q is zero."""
    tag = source_name(signals, node, gates).removeprefix("source_")
    return tuple(f"n{i + 1 if len(signals) > 1 else ''}_{tag}" for i, g in enumerate(gates) if g is None)


def new_link(a: str, b: str, key: str, name: str | None = None, gate: str | None = None, on: bool = True) -> Build:
    """A link between two nodes the model does not link, from NESTED_RESISTANCE (none); `gate`: an on/off signal,
    the link there only while it is on (`on`) or off (a path that opens and closes with the clutch)."""
    resistance = name or (f"R_{a}{b}" if gate is None else f"R_{a}{b}_{_slug(gate)}_{'on' if on else 'off'}")

    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        law = gated(gate, ch, on, resistance, repr(OPEN_CIRCUIT)) if gate else resistance

        def edit(doc: Doc) -> None:
            _add_link(doc, a, b, resistance, law, "K/W")
        return revise(model, key, edit)
    return build


def _add_link(doc: Doc, a: str, b: str, resistance: str, law: str, unit: str) -> None:
    """A link between a and b (nodes, or a node and a boundary) of resistance `law`, its parameter `resistance` from
    NESTED_RESISTANCE (none)."""
    doc["links"].append({"name": resistance, "between": [a, b], "resistance": law})
    _parameter(doc, resistance, NESTED_RESISTANCE, 1e-3, 10 * NESTED_RESISTANCE, unit)


def extra_node(ends: tuple[str, ...], key: str, mass: str) -> Build:
    """A thermal mass the model lacks: node `mass` hung on one node, or bridging two (a cover between a part and
    the air). Nested: 1 J/K hung (to first order more capacity on its node), NESTED_RESISTANCE to either end
    when bridging."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        capacity = f"C_{mass}"
        links = [f"R_{end}{mass}" for end in ends]
        bridging = len(ends) > 1

        def edit(doc: Doc) -> None:
            doc["nodes"][mass] = capacity
            for end, r in zip(ends, links):
                doc["links"].append({"name": r, "between": [end, mass], "resistance": r})
                _parameter(doc, r, NESTED_RESISTANCE if bridging else 0.1, 1e-3, 10 * NESTED_RESISTANCE, "K/W")
            doc.setdefault("initial", {})[mass] = model.initial[ends[0]]
            _parameter(doc, capacity, 100.0 if bridging else NESTED_CAPACITY, 0.1, 1e5, "J/K")
        return revise(model, key, edit)
    return build


def capacity_law(channel: str, node: str) -> Build:
    """Node `node`'s capacity C as C·(1 + k·(ϑ − ϑ_ref)), ϑ its own temperature as `channel` measures it (the
    solver holds it per step, as it holds the |ΔT| and level laws), ϑ_ref the runs' median of it: the linear law of
    a metal's specific heat over some tens of kelvin. Nested at k = 0 (C itself); the state follows dϑ/dt = Q/C(ϑ),
    so the heat the node stores is ∫C dϑ and no heat is created."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        values = signal_values(channel, ch)
        reference = round(float(np.nanmedian(values)), 1)
        reach = float(np.nanmax(np.abs(values - reference))) or 1.0
        capacity = model.nodes[node]
        k = f"k_{capacity}"
        law = f"{capacity} * maximum(1.0 + {k} * ({channel} - {reference!r}), {CAPACITY_FLOOR!r})"

        def edit(doc: Doc) -> None:
            doc.setdefault("capacities", []).append({"node": node, "capacity": law})
            limit = (1.0 - CAPACITY_FLOOR) / reach
            _parameter(doc, k, 0.0, -limit, limit, "1/K (the capacity's change per kelvin, relative)",
                       scale=0.1 / reach)
        return revise(model, f"{CAPACITY_KEY}{_slug(channel)}", edit)
    return build


def capacity_candidates(model: ModelDefinition) -> list[Candidate]:
    """A capacity law (capacity_law) on each node a channel measures (its first output) whose capacity is constant."""
    measured: dict[str, str] = {}
    for output, node in model.outputs.items():
        measured.setdefault(node, output)
    varying = {c.node for c in model.capacities}
    return [Candidate(f"{CAPACITY_KEY}{_slug(channel)}", channel, "capacity",
                      f"C_{node} = C*(1 + k*({channel} - T_ref))",
                      f"the heat capacity of node {node} changes with its own temperature {channel} (a metal's "
                      "specific heat rises as it heats)", capacity_law(channel, node), nodes=(node,),
                      signals=(channel,))
            for node, channel in measured.items() if node not in varying]


def typical_resistance(model: ModelDefinition, values: Mapping[str, float]) -> float:
    """The geometric mean of the model's fitted plain link resistances (a parameter named as the whole law), K/W."""
    plain = [l.resistance.text for l in model.links if l.resistance.text in model.parameters]
    return float(np.exp(np.mean([np.log(values[name]) for name in plain]))) if plain else 1.0


def node_probes(model: ModelDefinition, ends: tuple[str, ...], mass: str) -> Callable[[Mapping[str, float]],
                                                                                   list[dict[str, float]]]:
    """Screening starts of an extra node: its capacity a tenth of and equal to its (first) neighbour's, each link the
    model's typical resistance."""
    def probes(values: Mapping[str, float]) -> list[dict[str, float]]:
        r = typical_resistance(model, values)
        capacity = values.get(model.nodes[ends[0]], 1000.0)
        return [{f"C_{mass}": share * capacity, **{f"R_{end}{mass}": r for end in ends}} for share in (0.1, 1.0)]
    return probes


#: Screening starts of a new link, as multiples of the model's typical resistance: a path several times weaker than the
#: typical link scores worse than its parent from the typical one alone (the whole step counts there)
LINK_PROBE_FACTORS = (1.0, 10.0)


def link_probes(model: ModelDefinition, resistance: str, factors: tuple[float, ...] = LINK_PROBE_FACTORS
                ) -> Callable[[Mapping[str, float]], list[dict[str, float]]]:
    """Screening starts of a new link: the model's typical resistance times each of `factors` (by default it and ten
    times it). From NESTED_RESISTANCE a short fit moves its logarithm too little (a path of 0.3 K/W reached 0.86 of
    the parent's cost in 8 evaluations, 0.07 from the typical one); from the typical one alone a weaker path can
    score worse than its parent and is never fitted (a plate–flywheel path of 0.6 K/W while clamped on the linear
    baseline, typical 0.19 K/W: cost 12.86 against the parent's 12.49, ranked 258th, while its fit reaches 1.51)."""
    return lambda values: [{resistance: factor * typical_resistance(model, values)} for factor in factors]


def repoint_probes(model: ModelDefinition, boundary: str) -> Callable[[Mapping[str, float]], list[dict[str, float]]]:
    """Screening starts of a re-pointed boundary (no nested start: the links now reach another temperature): its plain
    links at their current resistance and at 10 and 100 times it (a link fitted to the wrong boundary is often
    strong where the right one is weak)."""
    plain = [l.resistance.text for l in model.links if boundary in l.between and l.resistance.text in model.parameters]

    def probes(values: Mapping[str, float]) -> list[dict[str, float]]:
        return [{name: factor * values[name] for name in plain if name in values} for factor in (1.0, 10.0, 100.0)]
    return probes


def sensor_lag(output: str, node: str) -> Build:
    """The sensor of `output` follows its node with a first-order lag, from NESTED_LAG_S."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tau = lag_time_constant(output)

        def edit(doc: Doc) -> None:
            doc["lags"].append({"output": output, "node": node, "time_constant": tau})
            _parameter(doc, tau, NESTED_LAG_S, 0.001, 600.0, "s")
        return revise(model, "sensor_lag" if output == "T_flywheel" else f"sensor_lag_{output}", edit)
    return build


def _calibrate(doc: Doc, output: str, **terms: str) -> None:
    """Add calibration terms (gain, offset, drift: parameter names) to the output's entry of `calibrations`, one
    entry per output (a drift found after an offset, or both built into one model, join its entry)."""
    entries = doc.setdefault("calibrations", [])
    entry = next((e for e in entries if e["output"] == output), None)
    if entry is None:
        entries.append({"output": output, **terms})
    else:
        entry.update(terms)


def sensor_calibration(output: str) -> Build:
    """The sensor of `output` reads gain * T + offset (benchlab.network.sensors), from gain 1 and offset 0 K: exactly
    the parent."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        gain, offset = calibration_parameters(output)

        def edit(doc: Doc) -> None:
            _calibrate(doc, output, gain=gain, offset=offset)
            _parameter(doc, gain, 1.0, *CALIBRATION_GAIN, "1")
            _parameter(doc, offset, 0.0, -CALIBRATION_OFFSET_K, CALIBRATION_OFFSET_K, "K", scale=1.0)
        return revise(model, f"{CALIBRATION_KEY}{output}", edit)
    return build


def sensor_drift(output: str) -> Build:
    """The sensor of `output` reads T + drift * t (t from the run's first sample), from a drift of 0 K/s: exactly the
    parent."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        drift = f"drift_{output}"

        def edit(doc: Doc) -> None:
            _calibrate(doc, output, drift=drift)
            _parameter(doc, drift, 0.0, -CALIBRATION_DRIFT_K_PER_S, CALIBRATION_DRIFT_K_PER_S, "K/s", scale=1e-4)
        return revise(model, f"{DRIFT_KEY}{output}", edit)
    return build


def drift_candidate(output: str, node: str) -> Candidate:
    """A sensor of `output` whose reading creeps in time: a sensor error, named as one, with what would confirm it."""
    return Candidate(f"{DRIFT_KEY}{output}", output, "sensor", f"{output} measured = {node} + drift * t",
                     f"the {output} sensor drifts (it reads the temperature of node {node} + drift x time): a sensor "
                     f"error, not physics; a known-temperature soak of the sensor or a second sensor on node {node} "
                     f"would confirm it", sensor_drift(output), nodes=(node,), signals=(output,))


def calibration_parameters(output: str) -> tuple[str, str]:
    """The gain (1) and offset (K) parameters of a calibration of `output`."""
    return f"gain_{output}", f"offset_{output}"


def calibration_candidate(output: str, node: str) -> Candidate:
    """Offset and gain of the sensor of `output`: a sensor error, named as one, with what would confirm it."""
    return Candidate(f"{CALIBRATION_KEY}{output}", output, "sensor",
                     f"{output} measured = gain * {node} + offset",
                     f"the {output} sensor is miscalibrated (it reads gain x the temperature of node {node} + offset): "
                     f"a sensor error, not physics; a known-temperature soak of the sensor or a second sensor on node "
                     f"{node} would confirm it", sensor_calibration(output), nodes=(node,), signals=(output,))


def lag_time_constant(output: str) -> str:
    """The time constant of a lag on `output` (tau_F for the clutch's flywheel, its earlier name)."""
    return "tau_F" if output == "T_flywheel" else f"tau_{output}"


def lag_probes(output: str) -> Callable[[Mapping[str, float]], list[dict[str, float]]]:
    """Screening starts of a sensor lag at LAG_PROBES_S: at 5 ms its effect is flat to first order."""
    return lambda values: [{lag_time_constant(output): tau} for tau in LAG_PROBES_S]


def moved_key(first: str, second: str, signal: str | None = None) -> str:
    """The key of moved_heat between two sources (with the signal its share follows)."""
    return f"split_{_slug(first)}_{_slug(second)}" + (f"_by_{_slug(signal)}" if signal else "")


def moved_heat(first: str, second: str, signal: str | None = None) -> Build:
    """A share of two sources' total heat moved from the second to the first, from a share of 0: a constant d, or
    d·(|s|/max)^n that follows a signal (a split that shifts with slip speed). Heat is moved, never made: the pair's
    sum is unchanged whatever the share."""
    key = moved_key(first, second, signal)

    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tag = key.removeprefix("split_")
        d = f"d_{tag}"
        share = d if signal is None else f"{d} * {factor_expression(signal, ch, f'n_{tag}')}"

        def edit(doc: Doc) -> None:
            a, b = (next(s for s in doc["sources"] if s["name"] == name) for name in (first, second))
            total = f"(({a['heat']}) + ({b['heat']}))"
            a["heat"], b["heat"] = f"({a['heat']}) + {share} * {total}", f"({b['heat']}) - {share} * {total}"
            _parameter(doc, d, 0.0, -0.45, 0.45, "1 (share of the pair's heat" + (
                ", at the signal's maximum)" if signal else ")"), scale=0.1)
            if signal is not None:
                _parameter(doc, f"n_{tag}", 1.0, EXPONENT_RANGE[0], EXPONENT_RANGE[1], "1 (exponent)")
        return revise(model, key, edit)
    return build


def piecewise_linear(signal: str, knots: np.ndarray, names: list[str]) -> str:
    """np.interp(signal, knots, values) as a model-file expression: flat beyond the outer knots."""
    s = signal_expression(signal)
    terms = [names[0]]
    for i in range(len(knots) - 1):
        lo, hi = float(knots[i]), float(knots[i + 1])
        terms.append(f"({names[i + 1]} - {names[i]}) * (minimum(maximum({s}, {lo!r}), {hi!r}) - {lo!r}) / {hi - lo!r}")
    return " + ".join(terms)


def fallback_source(signal: str, node: str) -> Build:
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


def link_groups(model: ModelDefinition) -> list[tuple[str, ...]]:
    """Links sharing one resistance law (R_PA = R_FA of the clutch) as one group, in the model's order."""
    groups: dict[str, list[str]] = {}
    for link in model.links:
        groups.setdefault(link.resistance.text, []).append(link.name)
    return [tuple(names) for names in groups.values()]


def link_difference(model: ModelDefinition, group: tuple[str, ...], channels: Channels) -> str | None:
    """The temperature difference across a link group, as a derived signal of the channels that measure its two
    ends (a node's first output, a boundary's channel in the runs): the first link of the group with both ends
    measured, None where none has. Laws of it are laws of node temperatures linearised about their measurements,
    like the radiation candidate: exact where the measurement is the node's temperature."""
    measured = {}
    for channel, node in model.outputs.items():
        measured.setdefault(node, channel)
    for boundary, reads in model.boundaries.items():
        present = [c for c in reads if c in channels]
        if present:
            measured[boundary] = present[0]
    for link in model.links:
        if link.name in group and all(end in measured for end in link.between):
            first, second = (measured[end] for end in link.between)
            if first in channels and second in channels and first != second:
                return difference_signal(first, second)
    return None


def _link_inert(links: tuple[str, ...], signal: str, law: str) -> tuple[str, ...]:
    """The parameter of link_law that has no effect while its factor g is zero."""
    tag = f"{_slug(signal)}_{_slug(links[0])}"
    return {"power": (f"n_{tag}",), "exponential": (f"k_{tag}",)}.get(law, ())


def _sources(signals: list[str], nodes: list[str], channels: Channels) -> list[Candidate]:
    """Heat sources into each node: one signal (an on/off one while on and while off), and the product of two (a
    continuous signal with another, or gated by an on/off one). A product names its first continuous signal: a gate
    says when the heat flows, the signal how much."""
    on_off = {s for s in signals if is_on_off(s, channels)}
    forms: list[tuple[tuple[str, ...], tuple[bool | None, ...]]] = []
    for s in signals:
        forms += [((s,), (g,)) for g in (True, False)] if s in on_off else [((s,), (None,))]
    for first, second in combinations(signals, 2):
        if first in on_off and second in on_off:
            continue
        gates = [(g, None) for g in (True, False)] if first in on_off else (
            [(None, g) for g in (True, False)] if second in on_off else [(None, None)])
        forms += [((first, second), g) for g in gates]
    out = []
    for node in nodes:
        for used, gates in forms:
            words = " x ".join(f"{s} ({'on' if g else 'off'})" if g is not None else s for s, g in zip(used, gates))
            law = "*".join(f"[{s} {'on' if g else 'off'}]" if g is not None else
                           (f"(|{s}|/max)^n{i + 1}" if len(used) > 1 else f"(|{s}|/max)^n")
                           for i, (s, g) in enumerate(zip(used, gates)))
            driver = next((s for s, g in zip(used, gates) if g is None), used[0])
            out.append(Candidate(source_name(used, node, gates), driver, "heat_source",
                                 f"heat into {node} = q*{law}", f"a heat source driven by {words} "
                                 f"warms node {node}", channel_source(used, node, gates), nodes=(node,),
                                 inert=source_exponents(used, node, gates), signals=used))
    return out


def generated(model: ModelDefinition, signals: list[str], channels: Channels,
              link_mechanism: Callable[[tuple[str, ...]], str] = lambda links: "convection") -> list[Candidate]:
    """Every extension of the model's structure (module docstring), physical ones first, learned flows last."""
    nodes = list(model.nodes)
    link_nodes = {l.name: tuple(n for n in l.between if n in model.nodes) for l in model.links}
    on_off = [s for s in signals if is_on_off(s, channels)]
    out, of_temperature = [], []  # laws of the signals, then (after every group's) laws of temperature differences
    for group in link_groups(model):
        where = tuple(dict.fromkeys(n for name in group for n in link_nodes[name]))
        for signal in path_signals(signals):
            for law in (LAWS[:1] if is_on_off(signal, channels) else LAWS):
                out.append(Candidate(f"{signal}_{law}_{'_'.join(group)}", signal, link_mechanism(group),
                                     f"{' = '.join(group)} = R * f({signal}), {law}",
                                     f"heat crosses {' and '.join(group)} at a rate that depends on {signal}",
                                     link_law(group, signal, law), nodes=where, inert=_link_inert(group, signal, law),
                                     signals=(signal,)))
        difference = link_difference(model, group, channels)
        if difference is not None:
            first, second = difference_channels(difference)
            for law in LAWS:
                of_temperature.append(Candidate(
                    _slug(f"dT_{first}_{second}_{law}_{'_'.join(group)}"), first, link_mechanism(group),
                    f"{' = '.join(group)} = R * f(|{first} - {second}|), {law}",
                    f"heat crosses {' and '.join(group)} at a rate that depends on the temperature difference "
                    f"{first} - {second} (natural or mixed convection, a contact that opens as it heats)",
                    link_law(group, difference, law), nodes=where, inert=_link_inert(group, difference, law),
                    signals=(first, second)))
    out += of_temperature
    out += _sources(signals, nodes, channels)
    linked = {frozenset(l.between) for l in model.links}
    for a, b in combinations(nodes, 2):
        if frozenset((a, b)) not in linked:
            out.append(Candidate(f"link_{a}_{b}", None, "conduction", f"new link R_{a}{b} between {a} and {b}",
                                 f"nodes {a} and {b} exchange heat directly", new_link(a, b, f"link_{a}_{b}"), nodes=(a, b),
                                 exact=False, probes=link_probes(model, f"R_{a}{b}"), adds_link=f"R_{a}{b}"))
            for gate in on_off:
                for on in (True, False):
                    state = "on" if on else "off"
                    out.append(Candidate(f"link_{a}_{b}_{gate}_{state}", gate, "conduction",
                                         f"new link R_{a}{b} between {a} and {b} while {gate} is {state}",
                                         f"nodes {a} and {b} exchange heat directly while {gate} is {state}",
                                         new_link(a, b, f"link_{a}_{b}_{gate}_{state}", gate=gate, on=on),
                                         nodes=(a, b), exact=False, signals=(gate,),
                                         probes=link_probes(model, f"R_{a}{b}_{_slug(gate)}_{state}")))
    for node in nodes:
        out.append(Candidate(f"extra_mass_{node}", None, "capacity", f"extra node X{node}: C_X{node} linked to {node}",
                             f"a thermal mass the model lacks stores and returns heat behind node {node}",
                             extra_node((node,), f"extra_mass_{node}", f"X{node}"), nodes=(node,), structural=True,
                             probes=node_probes(model, (node,), f"X{node}"), exact=False))
    for a, b in combinations(nodes, 2):
        out.append(Candidate(f"bridge_{a}_{b}", None, "capacity", f"extra node X{a}{b} linked to {a} and to {b}",
                             f"a thermal mass the model lacks sits between {a} and {b}",
                             extra_node((a, b), f"bridge_{a}_{b}", f"X{a}{b}"), nodes=(a, b), structural=True,
                             probes=node_probes(model, (a, b), f"X{a}{b}"), exact=False))
    out += capacity_candidates(model)
    lagged = {g.output for g in model.lags}
    for output, node in model.outputs.items():
        if output not in lagged:
            out.append(Candidate(f"sensor_lag_{output}", output, "sensor", f"{output} measured = first-order lag of {node}",
                                 f"the {output} sensor lags its node's temperature", sensor_lag(output, node),
                                 nodes=(node,), structural=True, probes=lag_probes(output), exact=False,
                                 signals=(output,)))
    scaled = {c.output for c in model.calibrations if c.gain or c.offset}
    drifting = {c.output for c in model.calibrations if c.drift}
    out += [calibration_candidate(output, node) for output, node in model.outputs.items() if output not in scaled]
    out += [drift_candidate(output, node) for output, node in model.outputs.items() if output not in drifting]
    for a, b in combinations(model.sources, 2):
        if a.node != b.node:
            signal = next(iter(sorted((a.heat.names | b.heat.names) - set(model.parameters) - set(model.nodes))), None)
            out.append(Candidate(moved_key(a.name, b.name), signal, "heat_split",
                                 f"{a.name} + d*(sum), {b.name} - d*(sum)",
                                 f"the heat of {a.name} and {b.name} is shared otherwise", moved_heat(a.name, b.name),
                                 nodes=(a.node, b.node)))
            for by in (s for s in signals if not is_on_off(s, channels)):
                tag = moved_key(a.name, b.name, by).removeprefix("split_")
                out.append(Candidate(moved_key(a.name, b.name, by), by, "heat_split",
                                     f"{a.name} + d*(|{by}|/max)^n*(sum), {b.name} - the same",
                                     f"the share of {a.name} and {b.name} in their heat shifts with {by}",
                                     moved_heat(a.name, b.name, by), nodes=(a.node, b.node), inert=(f"n_{tag}",),
                                     signals=(by, signal) if signal and signal != by else (by,)))
    return out


#: Laws of a link against its end's own temperature (smooth ones only where no |ΔT| law reads the link; a source: the
#: switching ones): smooth, a latch (a switch turned on at one threshold that the runs never take back below its
#: "off": on at or above "on", off only a whole range below the runs), a switch with hysteresis (on at or above "on",
#: off at or below on − band)
LEVEL_LAWS = ("linear", "power", "latch", "switch")
SWITCHING = ("latch", "switch")
#: Screening starts of a switch: its "on" threshold at these quantiles of the temperature in the runs, the band
#: between on and off these shares of its range (a thermostat's few kelvin of hysteresis in a range of tens)
SWITCH_QUANTILES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
SWITCH_BANDS = (0.03, 0.1, 0.3)
#: A switch's "on" threshold refined at this many evenly spaced points into each quantile interval beside its
#: best-scored start (a fifth of the interval apart: 0.2-0.3 K on the clutch's temperatures), its band at half and
#: twice the best (switch_refinements)
SWITCH_REFINE_POINTS = 4
#: A switch's "on" threshold may lie this share of the temperature's range beyond it: a thermostat that switches
#: at the runs' highest reading (the fan holds the temperature below it) is not on a bound
SWITCH_MARGIN = 0.25


def level_elements(model: ModelDefinition, channels: Channels, levels: "tuple[str, ...] | list[str]") -> list[
        tuple[str, str]]:
    """(channel, node or boundary) of each temperature in `levels` that measures a node (its output), and of each
    boundary that reads it, where the runs hold it and it varies: the elements whose own temperature a law may read."""
    out = []
    for channel in levels:
        if channel not in channels or not np.nanmax(channels[channel]) > np.nanmin(channels[channel]):
            continue
        node = model.outputs.get(channel)
        out += [(channel, node)] if node is not None else []
        out += [(channel, b) for b, reads in model.boundaries.items() if channel in reads]
    return out


def _level_terms(channel: str, tag: str, law: str, ch: Channels) -> tuple[str, dict]:
    """The factor of a level law on `channel` and its parameters besides the law's own factor: a switch
    hysteresis(T, on − band, on) (a latch: off a whole range below the runs' lowest), or (T − T_min)/span of the runs
    to the power n (linear: n = 1)."""
    values = signal_values(channel, ch)
    low, high = float(np.nanmin(values)), float(np.nanmax(values))
    span = high - low
    if law in SWITCHING:
        on, band = f"on_{tag}", f"band_{tag}"
        threshold = {on: (float(np.nanmedian(values)), low - SWITCH_MARGIN * span, high + SWITCH_MARGIN * span,
                          "degC (switched on at or above)", span / 10)}
        if law == "latch":
            return f"hysteresis({channel}, {low - span!r}, {on})", threshold
        return (f"hysteresis({channel}, {on} - {band}, {on})",
                {**threshold, band: (0.1 * span, 0.0, span, "K (switched off this far below on)", span / 10)})
    x = f"maximum({channel} - {low!r}, 0.0) / {span!r}"
    if law == "linear":
        return x, {}
    return f"({x}) ** n_{tag}", {f"n_{tag}": (1.0, EXPONENT_RANGE[0], EXPONENT_RANGE[1], "1 (exponent)", None)}


def level_key(channel: str, law: str, where: "tuple[str, ...] | str") -> str:
    """The key of a level law on links `where`, or of a level source into node `where`."""
    if isinstance(where, str):
        return f"source_level_{_slug(channel)}_{law}_{_slug(where)}"
    return _slug(f"level_{channel}_{law}_{'_'.join(where)}")


def level_law(links: tuple[str, ...], channel: str, law: str) -> Build:
    """The links' resistance R against the temperature of one of their ends, nested at R: R/(1 + g·f) with f a
    switch with hysteresis (a fan or valve a thermostat turns on and off) or ((T − T_min)/span)^n."""
    key = level_key(channel, law, links)

    def edit(doc: Doc, tag: str, factor: str) -> None:
        g = f"g_{tag}"
        _wrap_links(links, f"({{r}}) / (1.0 + {g} * {factor})")(doc)
        _parameter(doc, g, 0.0, -0.9, 1e3, "1 (factor on the conductance)", scale=0.5)
    return _level_build(key, key.removeprefix("level_"), channel, law, edit)


def _level_build(key: str, tag: str, channel: str, law: str, edit: Callable[[Doc, str, str], None]) -> Build:
    """The model with `edit` (its law's own parameter and where the factor enters) and the factor's parameters."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        factor, extra = _level_terms(channel, tag, law, ch)

        def edited(doc: Doc) -> None:
            edit(doc, tag, factor)
            for name, (start, lo, hi, unit, scale) in extra.items():
                _parameter(doc, name, start, lo, hi, unit, scale=scale)
        return revise(model, key, edited)
    return build


def level_source(channel: str, node: str, law: str) -> Build:
    """Heat q·f into `node`, q from 0 W, f a switch with hysteresis on its own temperature (a heater or cooler a
    thermostat switches) or ((T − T_min)/span)^n."""
    key = level_key(channel, law, node)

    def edit(doc: Doc, tag: str, factor: str) -> None:
        q = f"q_level_{tag}"
        doc["sources"].append({"name": key, "node": node, "heat": f"{q} * {factor}"})
        _parameter(doc, q, 0.0, -1e4, 1e4, "W (while on)" if law in SWITCHING else "W (at the runs' maximum)",
                   scale=10.0)
    return _level_build(key, key.removeprefix("source_level_"), channel, law, edit)


def _switch_grid(channel: str, ch: Channels) -> tuple[list[float], float]:
    """A switch's "on" thresholds to screen (SWITCH_QUANTILES of the temperature in the runs) and the runs' range."""
    values = signal_values(channel, ch)
    return [float(v) for v in np.nanquantile(values, SWITCH_QUANTILES)], float(np.nanmax(values) - np.nanmin(values))


def switch_probes(channel: str, tag: str, law: str, ch: Channels) -> Callable[[Mapping[str, float]],
                                                                          list[dict[str, float]]]:
    """Screening starts of a switch, its factor still 0 (the parent exactly: each start costs one column): "on" at
    SWITCH_QUANTILES of the temperature, a switch's band SWITCH_BANDS of its range."""
    ons, span = _switch_grid(channel, ch)
    bands = SWITCH_BANDS if law == "switch" else (None,)
    return lambda current: [{f"on_{tag}": on, **({f"band_{tag}": share * span} if share else {})}
                            for on in ons for share in bands]


def switch_refinements(channel: str, tag: str, law: str, ch: Channels) -> Callable[[Mapping[str, float]],
                                                                               list[dict[str, float]]]:
    """Starts near a switch's best-scored one, its factor still 0: "on" at SWITCH_REFINE_POINTS evenly spaced points
    into the quantile interval on each side of the best "on" (the band kept), and a switch's band at half and twice
    the best (within the temperature's range). Measured: a thermostat on the chamber air scored 290 from its best
    decile (30.1 degC), 183 at 30.5 degC, 445 at 31.0 (the plant's own threshold, which its lagging sensor reads
    late), so 0.5 K decided whether it or a smooth proxy on the housing (204) was screened."""
    grid, span = _switch_grid(channel, ch)
    ons = sorted(set(grid))
    fractions = [k / (SWITCH_REFINE_POINTS + 1) for k in range(1, SWITCH_REFINE_POINTS + 1)]

    def refine(best: Mapping[str, float]) -> list[dict[str, float]]:
        on, band = best[f"on_{tag}"], {k: v for k, v in best.items() if k == f"band_{tag}"}
        edges = [max((v for v in ons if v < on), default=None), min((v for v in ons if v > on), default=None)]
        out = [{f"on_{tag}": on + (edge - on) * f, **band} for edge in edges if edge is not None for f in fractions]
        if law == "switch":
            out += [{f"on_{tag}": on, f"band_{tag}": min(best[f"band_{tag}"] * factor, span)} for factor in (0.5, 2.0)]
        return out
    return refine


def _level_candidate(key: str, tag: str, channel: str, law: str, channels: Channels, **fields) -> Candidate:
    """A level candidate with what its law leaves inert at the nested start and, for a switch, its screening starts."""
    inert = {"linear": (), "power": (f"n_{tag}",), "latch": (f"on_{tag}",), "switch": (f"on_{tag}", f"band_{tag}")}
    switching = law in SWITCHING
    return Candidate(key, channel, signals=(channel,), inert=inert[law], nested_probes=switching,
                     probes=switch_probes(channel, tag, law, channels) if switching else None,
                     refine=switch_refinements(channel, tag, law, channels) if switching else None,
                     simpler=(key.replace("_switch_", "_latch_"),) if law == "switch" else (), **fields)


def carried_values(lead: Candidate, form: Candidate, values: Mapping[str, float]) -> dict[str, float]:
    """The lead's fitted values of its own parameters under the names its simpler form `form` gives them (a switch's
    "on" threshold and factor as its latch's): the form's start where it stands in for the lead."""
    def tag(key: str) -> str:
        return key.removeprefix("source_level_").removeprefix("level_")
    return {name.replace(tag(lead.key), tag(form.key)): value for name, value in values.items() if tag(lead.key) in name}


def _level_words(channel: str, law: str) -> str:
    return {"switch": "a switch with hysteresis on ", "latch": "a switch the runs turn on once (a latch) on ",
            "power": "a power of ", "linear": "a linear law of "}[law] + channel


def level_candidates(model: ModelDefinition, channels: Channels, levels: "tuple[str, ...] | list[str]",
                     link_mechanism: Callable[[tuple[str, ...]], str] = lambda links: "convection") -> list[Candidate]:
    """Laws of an element's own temperature level (not of a difference across a link): each link group at the node
    or boundary a temperature of `levels` measures, against that temperature (a latch, a switch with hysteresis;
    linear and power too where no |ΔT| law reads the difference across the group: a smooth law of one end's level
    only mimics it, and on natural convection was named in its place), and heat into that node (a latch, a switch).
    Like the |ΔT| laws they read the measurement, so the solver stays exact; the engine offers them for the
    temperatures its evidence ranks first."""
    out = []
    for channel, element in level_elements(model, channels, levels):
        for group in link_groups(model):
            if not any(element in l.between for l in model.links if l.name in group):
                continue
            where = tuple(dict.fromkeys(n for l in model.links if l.name in group for n in l.between
                                        if n in model.nodes))
            smooth = link_difference(model, group, channels) is None  # else the |ΔT| laws: a level is no better
            for law in LEVEL_LAWS if smooth else SWITCHING:
                key = level_key(channel, law, group)
                out.append(_level_candidate(
                    key, key.removeprefix("level_"), channel, law, channels, mechanism=link_mechanism(group),
                    extension=f"{' = '.join(group)} = R / (1 + g*f({channel})), {law}",
                    summary=f"heat crosses {' and '.join(group)} at a rate set by {_level_words(channel, law)}, the "
                            f"temperature of {element} itself (a fan or valve a thermostat switches, a property that "
                            "changes as it heats)", build=level_law(group, channel, law), nodes=where))
        if element in model.nodes:
            for law in SWITCHING:
                key = level_key(channel, law, element)
                out.append(_level_candidate(
                    key, key.removeprefix("source_level_"), channel, law, channels, mechanism="heat_source",
                    extension=f"heat into {element} = q*f({channel}), {law}",
                    summary=f"a heat flow set by {_level_words(channel, law)}, the temperature of node {element} "
                            "itself, warms or cools it (a heater or cooler a thermostat switches)",
                    build=level_source(channel, element, law), nodes=(element,)))
    return out


def unused_temperatures(model: ModelDefinition, channels: Channels, units: Mapping[str, str]) -> list[str]:
    """Measured temperatures of the runs that the model does not read and that vary: a boundary it could reach or
    should read instead (an engine-side temperature beside a model that ties the crankshaft to ambient). A sensor's
    own copy of an output (`T_flywheel_1` beside `T_flywheel`) measures a node of the model, not a boundary."""
    outputs = set(model.outputs) | set(model.simulated)
    return [c for c in sorted(channels) if units.get(c) == TEMPERATURE_UNIT and c not in model.channels()
            and c not in outputs and not any(c.startswith(f"{o}_") for o in outputs)
            and np.nanmax(channels[c]) > np.nanmin(channels[c])]


def repointed_boundary(boundary: str, channel: str, key: str) -> Build:
    """The boundary read from another measured channel: no new parameter, the same links."""
    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        def edit(doc: Doc) -> None:
            doc["boundaries"][boundary] = channel
        return revise(model, key, edit)
    return build


def boundary_link(node: str, channel: str, key: str) -> Build:
    """A link from `node` to a measured temperature the model does not read, as a new boundary `ext_<channel>`
    (boundaries and channels never share a name), from NESTED_RESISTANCE (none)."""
    resistance, boundary = f"R_{node}_{_slug(channel)}", f"ext_{_slug(channel)}"

    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        def edit(doc: Doc) -> None:
            doc["boundaries"][boundary] = channel
            _add_link(doc, node, boundary, resistance, resistance, "K/W")
        return revise(model, key, edit)
    return build


def unused_channel_candidates(model: ModelDefinition, temperatures: list[str],
                              link_mechanism: Callable[[tuple[str, ...]], str]) -> list[Candidate]:
    """Each unused measured temperature as the channel a boundary should read (re-pointed, its links' mechanism),
    and as a new boundary that each node could reach through a link of its own (conduction)."""
    out = []
    for channel in temperatures:
        for boundary, read in model.boundaries.items():
            links = tuple(l.name for l in model.links if boundary in l.between)
            key = f"boundary_{_slug(boundary)}_{_slug(channel)}"
            out.append(Candidate(key, channel, link_mechanism(links) if links else "conduction",
                                 f"boundary {boundary} = {channel} (was {read[0]})",
                                 f"boundary {boundary} follows {channel}, a measured channel the model does not read, "
                                 f"not {read[0]}", repointed_boundary(boundary, channel, key),
                                 nodes=tuple(n for l in model.links if boundary in l.between for n in l.between
                                             if n in model.nodes), exact=False, signals=(channel,),
                                 probes=repoint_probes(model, boundary)))
        for node in model.nodes:
            key = f"link_{_slug(node)}_{_slug(channel)}"
            out.append(Candidate(key, channel, "conduction", f"new link R_{node}_{channel} between {node} and {channel}",
                                 f"node {node} exchanges heat with {channel}, a measured channel the model does not "
                                 "read", boundary_link(node, channel, key), nodes=(node,), exact=False,
                                 signals=(channel,), probes=link_probes(model, f"R_{node}_{_slug(channel)}")))
    return out


def learned(signals: list[str], nodes: list[str]) -> list[Candidate]:
    """The learned piecewise-linear heat flows, one per signal and node: tried only where no physical term gains."""
    return [Candidate(f"learned_{signal}_{node}", signal, "other", f"learned heat flow into {node} = g({signal}), "
                      "piecewise linear", f"a heat flow into node {node} that depends on {signal}; no physical term "
                      "fits it", fallback_source(signal, node), physical=False, nodes=(node,))
            for signal in signals for node in nodes]


# --- the paper's clutch: the generator plus physical names ------------------------------------------------------

def engine_speed_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    """The convection law of the nonlinear clutch model file (eq. 11) in place of the constant R0, from a1 = a2 = 0
    (no effect), fitted linearly so that the first steps reach the scale of R0."""
    nonlinear = builtin("nonlinear")
    law = next(l.resistance.text for l in nonlinear.links if l.name == CONVECTION_LINKS[1])

    def edit(doc: Doc) -> None:
        for link in _links(doc, CONVECTION_LINKS):
            link["resistance"] = re.sub(r"\bR0\b", f"({law})", link["resistance"])
        for name in ("a1", "b1", "a2", "b2"):
            doc["parameters"][name] = nonlinear.to_doc()["parameters"][name]
        for name in ("a1", "a2"):
            doc["parameters"][name].update(start=0.0, min=-0.01, scale=0.1)
    return revise(model, "speed_convection", edit)


def state_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        _wrap_links(CONVECTION_LINKS, "({r}) * where(clutch_state >= 0.5, 1.0, k_open)")(doc)
        _parameter(doc, "k_open", 1.0, 0.2, 5.0, "1")
    return revise(model, "state_convection", edit)


def slip_convection(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    def edit(doc: Doc) -> None:
        _wrap_links(CONVECTION_LINKS, "({r}) / (1.0 + slip_gain * abs(engine_speed - clutch_speed) / 1000.0)")(doc)
        _parameter(doc, "slip_gain", 0.0, -0.2, 20.0, "1 per 1000 rpm of slip", scale=0.1)
    return revise(model, "slip_convection", edit)


def unequal_split(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    """The plate's share of the friction power `split` instead of the paper's half, the flywheel the rest: the shares
    are shifted, not rewritten, so a split found before (one that follows a signal) is kept."""
    def edit(doc: Doc) -> None:
        plate, flywheel = (next(s for s in doc["sources"] if s["name"] == name) for name in SHARES)
        plate["heat"] = f"({plate['heat']}) + (split - 0.5) * friction_power"
        flywheel["heat"] = f"({flywheel['heat']}) - (split - 0.5) * friction_power"
        _parameter(doc, "split", 0.5, 0.05, 0.95, "1 (plate share of P)", scale=0.5)
    return revise(model, "heat_split", edit)


RADIATION_PROBE_T_K = 323.15  # the temperature at which the radiation's screening start is set (50 degC)


def radiation_probes(model: ModelDefinition) -> Callable[[Mapping[str, float]], list[dict[str, float]]]:
    """Screening start of radiation: a linearised conductance a tenth of the model's typical link's (at its nested
    1e-5 m² the term is absorbed, to first order, by the links the model has)."""
    def probes(values: Mapping[str, float]) -> list[dict[str, float]]:
        per_m2 = STEFAN_BOLTZMANN * 4 * RADIATION_PROBE_T_K ** 3
        return [{"eps_area": 0.1 / typical_resistance(model, values) / per_m2}]
    return probes


def radiation(model: ModelDefinition, ch: Channels) -> ModelDefinition:
    """Grey-body exchange linearised about the measured temperatures: ε·A·σ·4·T̄³ per kelvin of difference."""
    law = f"1 / (eps_area * {STEFAN_BOLTZMANN!r} * 4 * ((T_flywheel + T_housing) / 2 + 273.15) ** 3)"

    def edit(doc: Doc) -> None:
        doc["links"] += [{"name": "radiation F", "between": ["F", "T"], "resistance": law},
                         {"name": "radiation P", "between": ["P", "T"], "resistance": law}]
        _parameter(doc, "eps_area", 1e-5, 1e-6, 2.0, "m2 (emissivity x area)")
    return revise(model, "radiation", edit)


CLUTCH_FALLBACK_SIGNALS = ("engine_speed", "slip_speed", "clutch_speed", "clutch_torque", "clutch_state",
                           "friction_power", "load_torque", "T_flywheel")
#: Generated keys of the clutch that keep the names (and parameters) they had before the generator.
CLUTCH_NAMED = {
    "clutch_state_linear_R_PA_R_FA": Candidate(
        "state_convection", "clutch_state", "convection", "R_FA = R_PA = f_R * (k_open if S = 0)",
        "convection differs between clamped and open clutch", state_convection, nodes=("P", "F", "A")),
    "slip_speed_linear_R_PA_R_FA": Candidate(
        "slip_convection", "slip_speed", "convection", "R_FA = R_PA = f_R / (1 + g*|slip_speed|/1000)",
        "heat leaves faster while slipping: convection grows with slip speed", slip_convection, nodes=("P", "F", "A")),
    "split_plate_share_flywheel_share": Candidate(
        "heat_split", "friction_power", "heat_split", "P_plate = s*P, P_flywheel = (1-s)*P",
        "friction heat is not split half and half between plate and flywheel", unequal_split, nodes=("P", "F")),
    "extra_mass_F": Candidate(
        "extra_mass", None, "capacity", "extra node XF: C_XF linked to the flywheel by R_FXF",
        "a thermal mass the model lacks stores and returns heat slowly", extra_node(("F",), "extra_mass", "XF"),
        nodes=("F",), structural=True),  # its probes are set from the model in clutch_candidates
    "sensor_lag_T_flywheel": Candidate(
        "sensor_lag", "T_flywheel", "sensor", "T_flywheel measured = first-order lag tau_F of the flywheel",
        "the flywheel sensor lags the flywheel temperature", sensor_lag("T_flywheel", "F"), nodes=("F",),
        structural=True),
    "link_P_F_clutch_state_on": Candidate(
        "clamped_conduction", "clutch_state", "conduction", "R_PF between plate and flywheel when S = 1",
        "plate and flywheel exchange heat through the clamped disc",
        new_link("P", "F", "clamped_conduction", "R_PF_clamped", gate="clutch_state"), nodes=("P", "F"), exact=False),  # probes
        # set from the model in clutch_candidates
}
CLUTCH_PARTS = {"P": "pressure plate", "F": "flywheel", "A": "chamber air", "T": "housing"}


def _clutch_mechanism(links: tuple[str, ...]) -> str:
    """Engine-side conduction on R_Feng; every other link of the clutch is convection (to the air or ambient)."""
    return "conduction" if links == ("R_Feng",) else "convection"


def clutch_candidates(model: ModelDefinition, channels: Channels, units: Mapping[str, str],
                      levels: "tuple[str, ...] | list[str]" = ()) -> list[Candidate]:
    """The clutch's library: the generator on the clutch signals with the physical names, eq. (11) where the
    baseline lacks it, the clamped plate–flywheel conduction and radiation, the measured temperatures it does not
    read as boundaries; learned flows into flywheel and air."""
    signals = library_signals(model, channels, units)
    out = [] if "a1" in model.parameters else [Candidate(
        "speed_convection", "engine_speed", "convection", "R_FA = R_PA = a*exp(b*engine_speed) + R0",
        "cool-down rate depends on engine speed: convection grows with engine speed", engine_speed_convection,
        nodes=("P", "F", "A"), inert=("b1", "b2"))]
    for cand in generated(model, signals, channels, _clutch_mechanism):
        named = CLUTCH_NAMED.get(cand.key)
        probes = link_probes(model, "R_PF_clamped") if named and named.key == "clamped_conduction" else cand.probes
        out.append(replace(named, probes=probes, exact=cand.exact, signals=cand.signals) if named
                   else replace(cand, summary=_clutch_words(cand.summary)))
    out += [Candidate("radiation", "T_flywheel", "other", "radiation eps_A*sigma*(T_F^4 - T_T^4) from plate and flywheel",
                      "hot plate and flywheel lose heat by radiation to the housing", radiation, nodes=("P", "F", "T"),
                      exact=False, probes=radiation_probes(model))]
    out += [replace(c, summary=_clutch_words(c.summary))
            for c in unused_channel_candidates(model, unused_temperatures(model, channels, units), _clutch_mechanism)]
    out += [replace(c, summary=_clutch_words(c.summary))
            for c in level_candidates(model, channels, levels, _clutch_mechanism)]
    return out + learned([s for s in CLUTCH_FALLBACK_SIGNALS if _available(s, channels)], ["F", "A"])


def _clutch_words(text: str) -> str:
    """A generated summary with the clutch's parts named (node P is the pressure plate, …)."""
    return re.sub(r"\bnode ([PFAT])\b", lambda m: f"the {CLUTCH_PARTS[m.group(1)]}", text)


# --- any network -------------------------------------------------------------------------------------------------

def _available(signal: str | None, channels: Channels) -> bool:
    """Whether the runs hold the signal a candidate depends on."""
    if signal is None:
        return True
    if signal == "slip_speed":
        return "engine_speed" in channels and "clutch_speed" in channels
    return signal in channels


def is_clutch(model: ModelDefinition) -> bool:
    """Whether the model has the paper's clutch structure the clutch names refer to (nodes, convection links, shares)."""
    return (set(CLUTCH_NODES) <= set(model.nodes) and set(CONVECTION_LINKS) <= {l.name for l in model.links}
            and set(SHARES) <= {s.name for s in model.sources})


def library_signals(model: ModelDefinition, channels: Channels, units: Mapping[str, str]) -> list[str]:
    """The signals the library's laws read: the clutch's where the model has the paper's clutch structure, else the
    network's inputs."""
    if is_clutch(model):
        return [s for s in CLUTCH_SIGNALS if _available(s, channels) and np.ptp(signal_values(s, channels)) > 0]
    return network_signals(model, channels, units)


def network_signals(model: ModelDefinition, channels: Channels, units: Mapping[str, str]) -> list[str]:
    """The signals a missing effect of a network may depend on: the inputs its laws read (speeds, currents,
    powers; not temperatures, which are its states and boundaries), where the runs hold them and they vary.
    A model names the inputs that matter on its bench; every other channel of a run would multiply the fits."""
    return [c for c in sorted(model.law_channels()) if c in channels and units.get(c) != TEMPERATURE_UNIT
            and np.nanmax(channels[c]) > np.nanmin(channels[c])]


def candidates(model: ModelDefinition, channels: Channels, units: Mapping[str, str] | None = None,
               levels: "tuple[str, ...] | list[str]" = ()) -> list[Candidate]:
    """The library for this model, none on a channel the runs lack (`load_torque` is optional in a run file);
    `levels`: the measured temperatures whose own level laws are offered (level_candidates)."""
    units = dict(units or {})
    if is_clutch(model):
        found = clutch_candidates(model, channels, units, levels)
    else:
        signals = network_signals(model, channels, units)
        found = (generated(model, signals, channels)
                 + unused_channel_candidates(model, unused_temperatures(model, channels, units), lambda links: "convection")
                 + level_candidates(model, channels, levels)
                 + learned(signals, list(model.nodes)))
    return [c for c in found if all(_available(s, channels) for s in c.reads)]


PER_GROUP = "per_run"  # the mechanism of a parameter the runs disagree on


def per_group_candidates(model: ModelDefinition, names: "list[str]", group_by: str = "run") -> list[Candidate]:
    """With several runs (or run groups, `--group-by`): for each parameter in `names`, "the runs need different
    values of it" (the bench, the day or the specimen differ). It adds no physics: the model is unchanged and the
    parameter is fitted once per group, judged like any other extension by what it gains on held-out blocks of the
    same runs. Its nodes are those whose laws read it (the capacity's node, a link's two ends, a source's node)."""
    out = []
    for name in names:
        nodes = [n for n, capacity in model.nodes.items() if capacity == name]
        nodes += [n for link in model.links if name in link.resistance.names for n in link.between]
        nodes += [s.node for s in model.sources if name in s.heat.names]
        out.append(Candidate(f"{PER_GROUP}_{name}", None, PER_GROUP, f"{name}@<{group_by}>",
                             f"the runs disagree on {name}: fitted once per {group_by}, the model otherwise unchanged",
                             lambda model, channels: model, nodes=tuple(n for n in dict.fromkeys(nodes)
                                                                         if n in model.nodes),
                             splits=(name,)))
    return out


#: A new link's conductance against a signal x = |s|/max, times 1/R: none at x = 0 (where the link is no link), so
#: a contact that only a torque or a speed closes is inside the bounds, not on them
CONDUCTANCE_LAWS = {"linear": "{x}", "power": "({x})^n", "exponential": "(1 - exp(-k*{x}))"}


def signal_link(a: str, b: str, key: str, signal: str, law: str) -> Build:
    """A link between two nodes the model does not link whose conductance is CONDUCTANCE_LAWS[law] / R, from
    NESTED_RESISTANCE (none)."""
    resistance = f"R_{a}{b}"

    def build(model: ModelDefinition, ch: Channels) -> ModelDefinition:
        tag = f"{_slug(signal)}_{resistance}"
        x = f"abs({signal_expression(signal)}) / {_reference(signal, ch)!r}"
        share = {"linear": x, "power": f"({x}) ** n_{tag}", "exponential": f"(1.0 - exp(-k_{tag} * {x}))"}[law]

        def edit(doc: Doc) -> None:
            _add_link(doc, a, b, resistance, f"{resistance} / maximum({share}, {MIN_SHARE!r})",
                      "K/W (at the signal's maximum)")
            if law == "power":
                _parameter(doc, f"n_{tag}", 1.0, EXPONENT_RANGE[0], EXPONENT_RANGE[1], "1 (exponent)")
            if law == "exponential":
                _parameter(doc, f"k_{tag}", 3.0, 0.1, 30.0, "1 (rate over the signal's range)")
        return revise(model, key, edit)
    return build


def composed_links(model: ModelDefinition, channels: Channels, units: Mapping[str, str],
                   groups: tuple[str, ...]) -> list[Candidate]:
    """Two steps in one round: a new link between two nodes the model does not link, together with its
    resistance fitted once per run group (a contact that changes run by run, as a lining wears) and together
    with each law of a continuous signal (a contact conductance that grows with the clamping torque). Alone, such
    a link can gain too little to be chosen (a link at the runs' mean conductance explains little of a contact
    that varies), so the greedy search would never take the second step that explains it."""
    continuous = [s for s in path_signals(library_signals(model, channels, units)) if not is_on_off(s, channels)]
    linked = {frozenset(l.between) for l in model.links}
    words = _clutch_words if is_clutch(model) else (lambda text: text)
    out = []
    for a, b in combinations(list(model.nodes), 2):
        if frozenset((a, b)) in linked:
            continue
        resistance, plain = f"R_{a}{b}", new_link(a, b, f"link_{a}_{b}")
        probes = link_probes(model, resistance)
        spread = link_probes(model, resistance, COMPOSED_PROBES)
        if len(groups) > 1:
            out.append(Candidate(
                f"link_{a}_{b}_{PER_GROUP}", None, "conduction", f"new link {resistance}@<group> between {a} and {b}",
                words(f"nodes {a} and {b} exchange heat directly, through a resistance that differs between the run "
                      "groups (a contact that changes run by run)"), plain, nodes=(a, b), exact=False,
                splits=(resistance,), composed=True, adds_link=resistance,
                probes=lambda values, probe=probes: [{f"{k}@{g}": v for k, v in p.items() for g in groups}
                                                     for p in probe(values)]))
        for signal in continuous:
            for law, shape in CONDUCTANCE_LAWS.items():
                out.append(Candidate(
                    f"link_{a}_{b}_{_slug(signal)}_{law}", signal, "conduction",
                    f"new link between {a} and {b} of conductance {shape.format(x=f'|{signal}|/max')} / {resistance}",
                    words(f"nodes {a} and {b} exchange heat directly, through a conductance that grows with {signal} "
                          "(none where it is zero: a contact pressed by it)"),
                    signal_link(a, b, f"link_{a}_{b}_{_slug(signal)}_{law}", signal, law), nodes=(a, b),
                    exact=False, signals=(signal,), composed=True, probes=spread, adds_link=resistance))
    return out


def applies(cand: Candidate, model: ModelDefinition) -> bool:
    """Whether the candidate still extends the model: not where it would add a link the model already has."""
    return cand.adds_link is None or cand.adds_link not in {link.name for link in model.links}


def telling_apart(model: ModelDefinition, first: Candidate, second: Candidate) -> str:
    """The measurement that would tell two candidate extensions apart: a soak or a second sensor where one is a
    sensor's calibration; a sensor on a node either changes that the model does not measure (both change its heat
    balance differently); else runs in which their signals vary
    independently; else longer runs (more blocks for the test between them)."""
    if first.splits or second.splits:
        return ("runs of each group with the other's conditions: the same bench, day and specimen as the other "
                "runs, where the parameter's difference would vanish and the other explanation's would not")
    calibration = next((c for c in (first, second) if c.key.startswith((CALIBRATION_KEY, DRIFT_KEY))), None)
    if calibration is not None:
        return (f"a known-temperature soak of the {calibration.signal} sensor or a second sensor on node "
                f"{calibration.nodes[0]}: a sensor error shows on that sensor alone")
    measured = set(model.outputs.values())
    channel_of = {node: channel for channel, node in {**model.simulated, **model.outputs}.items()}
    unmeasured = sorted(n for n in set(first.nodes) | set(second.nodes) if n in model.nodes and n not in measured)
    if unmeasured:
        return "a sensor on " + " and ".join(
            f"node {n}" + (f" ({channel_of[n]})" if n in channel_of else "") for n in unmeasured)
    if first.signal and second.signal and first.signal != second.signal:
        return f"runs in which {first.signal} and {second.signal} vary independently"
    return "longer runs: more blocks for the test between the two"
