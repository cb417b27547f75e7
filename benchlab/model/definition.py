"""Model files (contract section 6, TOML `schema = "benchlab-model/1"`): read, check, write.

One module parses and checks a model, from a TOML file or from the `"network"` object of a parameter file;
every defect is an InputError naming the file, the entry and what was expected (exit 2). The checked
`ModelDefinition` is plain data: the thermal network is built from it (benchlab.model.build), diagnose
edits it, and it is written back as TOML (`to_toml`) or JSON (`to_doc`) unchanged in meaning.
"""

from __future__ import annotations

import json
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from benchlab.errors import InputError, read_document
from benchlab.model.expressions import Expression, ExpressionError, affine_parts, parse
from benchlab.values import check_keys, finite_number

SCHEMA = "benchlab-model/1"
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
TOP_KEYS = ("schema", "name", "description", "requires", "nodes", "capacities", "boundaries", "links", "sources",
            "lags", "calibrations", "outputs", "simulated", "initial", "parameters")
PARAMETER_KEYS = ("start", "min", "max", "unit", "fixed", "scale")
CALIBRATION_TERMS = ("gain", "offset", "drift")  # reading = gain * T + offset + drift * t (benchlab.network.sensors)


@dataclass(frozen=True)
class Parameter:
    """A parameter's starting value, bounds and unit; `fixed` holds it at a value; `scale` is the fit's step
    for a signed parameter (default |start|)."""

    name: str
    start: float
    min: float
    max: float
    unit: str = ""
    fixed: float | None = None
    scale: float | None = None


@dataclass(frozen=True)
class LinkEntry:
    """Heat flow (ϑ_a − ϑ_b) / resistance between two nodes or a node and a boundary."""

    name: str
    between: tuple[str, str]
    resistance: Expression


@dataclass(frozen=True)
class CapacityEntry:
    """A node's heat capacity (J/K) as a law of parameters and channels, in place of its [nodes] parameter alone: a
    capacity that varies with the node's own temperature, read from the channel that measures it."""

    node: str
    capacity: Expression


@dataclass(frozen=True)
class SourceEntry:
    """Heat flow into a node (W), possibly affine in node temperatures."""

    name: str
    node: str
    heat: Expression


@dataclass(frozen=True)
class LagEntry:
    """A first-order sensor: the measured channel `output` follows `node` with time constant parameter."""

    output: str
    node: str
    time_constant: str


@dataclass(frozen=True)
class CalibrationEntry:
    """A miscalibrated sensor: the measured channel `output` reads gain * T + offset + drift * t (each a parameter
    name, None where the file leaves it out: 1, 0 K, 0 K/s)."""

    output: str
    gain: str | None = None
    offset: str | None = None
    drift: str | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(n for n in (self.gain, self.offset, self.drift) if n)


@dataclass(frozen=True)
class ModelDefinition:
    """A checked model file. `alias` is the built-in name (linear, nonlinear) it was loaded under, if any."""

    name: str
    nodes: dict[str, str]  # node -> capacity parameter
    boundaries: dict[str, tuple[str, ...]]  # boundary -> channels, the first present one is used
    links: tuple[LinkEntry, ...]
    sources: tuple[SourceEntry, ...]
    lags: tuple[LagEntry, ...]
    outputs: dict[str, str]  # measured channel -> node
    simulated: dict[str, str]  # further channel simulate writes -> node
    initial: dict[str, str]  # state -> channel it starts from (complete: every node and lag)
    parameters: dict[str, Parameter]
    requires: tuple[str, ...] = ()  # run channels required beyond those named (the clutch's section 1 list)
    description: str = ""
    source: str = field(default="<model>", compare=False)  # where it was read from, for error messages
    alias: str | None = field(default=None, compare=False)
    calibrations: tuple[CalibrationEntry, ...] = ()
    capacities: tuple[CapacityEntry, ...] = ()

    @property
    def label(self) -> str:
        """The name commands print and parameter files carry: the built-in alias where there is one."""
        return self.alias or self.name

    def law_channels(self) -> set[str]:
        """Channels that resistances, heat flows and capacity laws read."""
        named = set().union(*(l.resistance.names for l in self.links), *(s.heat.names for s in self.sources),
                            *(c.capacity.names for c in self.capacities))
        return named - set(self.parameters) - set(self.nodes)

    def channels(self) -> list[str]:
        """Every run channel the model names: laws, boundaries, outputs, initial states, `requires`."""
        names = [*self.requires, *sorted(self.law_channels()), *(c for cs in self.boundaries.values() for c in cs),
                 *self.outputs, *self.initial.values()]
        return list(dict.fromkeys(names))

    def required_channels(self) -> list[str]:
        """Channels a run must hold: all named ones except the fall-backs of a boundary list (T_engine may be absent)."""
        optional = {c for cs in self.boundaries.values() if len(cs) > 1 for c in cs}
        needed = {c for cs in self.boundaries.values() if len(cs) > 1 for c in cs[-1:]}
        return [c for c in self.channels() if c not in optional or c in needed]

    def free_parameters(self) -> list[Parameter]:
        return [p for p in self.parameters.values() if p.fixed is None]

    def lag_state(self, output: str) -> str:
        """The state name of the sensor lag on `output` (the channel's own name: channels and nodes never collide)."""
        return output

    def with_starts(self, values: Mapping[str, float], name: str | None = None) -> "ModelDefinition":
        """The same model starting from `values` where it names them (clamped to the bounds): a fitted model to re-fit."""
        params = {k: replace(p, start=min(max(float(values[k]), p.min), p.max)) if k in values and p.fixed is None
                  else p for k, p in self.parameters.items()}
        return replace(self, parameters=params, name=name or self.name, alias=None)

    def with_fixed(self, values: Mapping[str, float]) -> "ModelDefinition":
        """The same model with the named parameters held at the given values (a parameter on its bound, held while
        diagnose judges what an extension adds)."""
        params = {k: replace(p, fixed=float(values[k])) if k in values else p for k, p in self.parameters.items()}
        return replace(self, parameters=params)

    def to_doc(self) -> dict[str, Any]:
        """The model file's tables as plain data (TOML or the parameter file's JSON "network")."""
        doc: dict[str, Any] = {"schema": SCHEMA, "name": self.name}
        if self.description:
            doc["description"] = self.description
        if self.requires:
            doc["requires"] = list(self.requires)
        doc["nodes"] = dict(self.nodes)
        doc["capacities"] = [{"node": c.node, "capacity": c.capacity.text} for c in self.capacities]
        doc["boundaries"] = {k: (v[0] if len(v) == 1 else list(v)) for k, v in self.boundaries.items()}
        doc["links"] = [{"name": l.name, "between": list(l.between), "resistance": l.resistance.text} for l in self.links]
        doc["sources"] = [{"name": s.name, "node": s.node, "heat": s.heat.text} for s in self.sources]
        doc["lags"] = [{"output": g.output, "node": g.node, "time_constant": g.time_constant} for g in self.lags]
        doc["calibrations"] = [{"output": c.output, **{term: name for term, name in zip(CALIBRATION_TERMS,
                                                                                  (c.gain, c.offset, c.drift)) if name}}
                               for c in self.calibrations]
        doc["outputs"] = dict(self.outputs)
        doc["simulated"] = dict(self.simulated)
        doc["initial"] = dict(self.initial)
        doc["parameters"] = {name: {k: v for k, v in (("start", p.start), ("min", p.min), ("max", p.max),
                                                      ("unit", p.unit), ("fixed", p.fixed), ("scale", p.scale))
                                    if v is not None} for name, p in self.parameters.items()}
        return {k: v for k, v in doc.items() if v not in ([], {})}


def _fail(source: str, entry: str, expected: str) -> InputError:
    return InputError(source, entry, expected)


def is_name(value: object) -> bool:
    """The name rule of model files (nodes, parameters, the channels they read): letters, digits and _, not starting
    with a digit or __; also what a run file's channel may be called (an HDF5 dataset and an expression's name)."""
    return isinstance(value, str) and NAME.match(value) is not None and not value.startswith("__")


def _name(source: str, entry: str, value: object, what: str) -> str:
    if not is_name(value):
        raise _fail(source, entry, f"{what}: a name of letters, digits and _, got {value!r}")
    return value


def _table(source: str, entry: str, value: object) -> dict:
    if not isinstance(value, dict):
        raise _fail(source, entry, f"a table, got {type(value).__name__}")
    return value


def _entries(source: str, entry: str, value: object) -> list[dict]:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise _fail(source, entry, "an array of tables ([[" + entry.rsplit(".", 1)[-1] + "]])")
    return value


def _keys(source: str, entry: str, table: dict, allowed: tuple[str, ...], required: tuple[str, ...]) -> None:
    check_keys(source, entry, table, allowed)
    for key in required:
        if key not in table:
            raise _fail(source, f"{entry}.{key}", "present (missing)")


def _number(source: str, entry: str, value: object) -> float:
    number = finite_number(value)
    if number is None:
        raise _fail(source, entry, f"a finite number, got {value!r}")
    return number


def _expression(source: str, entry: str, text: object) -> Expression:
    try:
        return parse(text)
    except ExpressionError as exc:
        raise _fail(source, entry, str(exc)) from None


def _parameters(source: str, prefix: str, doc: dict) -> dict[str, Parameter]:
    out = {}
    for name, table in _table(source, f"{prefix}parameters", doc.get("parameters", {})).items():
        entry = f"{prefix}parameters.{name}"
        _name(source, entry, name, "a parameter name")
        table = _table(source, entry, table)
        _keys(source, entry, table, PARAMETER_KEYS, ("min", "max") + (() if "fixed" in table else ("start",)))
        low, high = _number(source, f"{entry}.min", table["min"]), _number(source, f"{entry}.max", table["max"])
        if low > high:
            raise _fail(source, entry, f"min <= max, got min {low:g} > max {high:g}")
        fixed = _number(source, f"{entry}.fixed", table["fixed"]) if "fixed" in table else None
        start = _number(source, f"{entry}.start", table["start"]) if "start" in table else fixed
        if not low <= start <= high:
            raise _fail(source, f"{entry}.start", f"a value in [min, max] = [{low:g}, {high:g}], got {start:g}")
        scale = _number(source, f"{entry}.scale", table["scale"]) if "scale" in table else None
        if scale is not None and scale <= 0:
            raise _fail(source, f"{entry}.scale", f"a positive step, got {scale:g}")
        unit = table.get("unit", "")
        if not isinstance(unit, str):
            raise _fail(source, f"{entry}.unit", f"a unit string, got {unit!r}")
        out[name] = Parameter(name, start, low, high, unit, fixed, scale)
    return out


def _positive(source: str, entry: str, param: Parameter, what: str) -> None:
    if param.min <= 0:
        raise _fail(source, f"parameters.{param.name}.min", f"> 0 ({param.name} is {what}, named by {entry})")


def parse_model(doc: object, source: "str | os.PathLike[str]", prefix: str = "") -> ModelDefinition:
    """Check a model document (TOML tables, or a parameter file's "network" with prefix "network.")."""
    source = str(source)
    doc = _table(source, prefix.rstrip(".") or "file", doc)
    _keys(source, prefix.rstrip(".") or "file", doc, TOP_KEYS, ("schema", "nodes", "outputs", "parameters"))
    if doc["schema"] != SCHEMA:
        raise _fail(source, f"{prefix}schema", f"{SCHEMA!r}, got {doc['schema']!r}")
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise _fail(source, f"{prefix}name", f"a model name, got {name!r}")
    params = _parameters(source, prefix, doc)
    nodes = {}
    for node, capacity in _table(source, f"{prefix}nodes", doc["nodes"]).items():
        entry = f"{prefix}nodes.{node}"
        _name(source, entry, node, "a node name")
        if capacity not in params:
            raise _fail(source, entry, f"its heat-capacity parameter, with a [parameters.{capacity}] table")
        _positive(source, entry, params[capacity], "a heat capacity")
        nodes[node] = capacity
    if not nodes:
        raise _fail(source, f"{prefix}nodes", "at least one node")
    boundaries = {}
    for boundary, channels in _table(source, f"{prefix}boundaries", doc.get("boundaries", {})).items():
        entry = f"{prefix}boundaries.{boundary}"
        _name(source, entry, boundary, "a boundary name")
        channels = [channels] if isinstance(channels, str) else channels
        if not isinstance(channels, list) or not channels:
            raise _fail(source, entry, "a channel name or a list of channel names")
        boundaries[boundary] = tuple(_name(source, entry, c, "a channel") for c in channels)
    for name_ in set(nodes) & set(boundaries) | set(nodes) & set(params) | set(boundaries) & set(params):
        raise _fail(source, f"{prefix}nodes.{name_}" if name_ in nodes else f"{prefix}boundaries.{name_}",
                    "a name no node, boundary or parameter shares")
    links = _links(source, prefix, doc, nodes, boundaries, params)
    capacities = _capacities(source, prefix, doc, nodes, boundaries)
    sources = _sources(source, prefix, doc, nodes, boundaries, params)
    outputs = _outputs(source, f"{prefix}outputs", doc["outputs"], nodes, params)
    simulated = _outputs(source, f"{prefix}simulated", doc.get("simulated", {}), nodes, params)
    if not outputs:
        raise _fail(source, f"{prefix}outputs", "at least one measured channel = node")
    lags = _lags(source, prefix, doc, nodes, outputs, params)
    calibrations = _calibrations(source, prefix, doc, outputs, params)
    initial = _initial(source, prefix, doc, nodes, outputs, lags, params)
    requires = doc.get("requires", [])
    if not isinstance(requires, list):
        raise _fail(source, f"{prefix}requires", "a list of channel names")
    description = doc.get("description", "")
    if not isinstance(description, str):
        raise _fail(source, f"{prefix}description", "a string")
    model = ModelDefinition(name, nodes, boundaries, links, sources, lags, outputs, simulated, initial, params,
                            tuple(_name(source, f"{prefix}requires", c, "a channel") for c in requires),
                            description, source, calibrations=calibrations, capacities=capacities)
    _check_names(model, prefix)
    return model


def _named_entries(source: str, prefix: str, doc: dict, table: str,
                   keys: tuple[str, ...]) -> list[tuple[str, str, dict]]:
    """(name, entry for messages, table) of each entry of an array of tables, every key of `keys` present."""
    out = []
    for i, item in enumerate(_entries(source, f"{prefix}{table}", doc.get(table, []))):
        name = item.get("name") if isinstance(item.get("name"), str) else str(i)
        entry = f"{prefix}{table}[{name}]"
        _keys(source, entry, item, keys, keys)
        out.append((name, entry, item))
    _unique(source, f"{prefix}{table}", [name for name, _, _ in out])
    return out


def _links(source, prefix, doc, nodes, boundaries, params) -> tuple[LinkEntry, ...]:
    out = []
    for label, entry, table in _named_entries(source, prefix, doc, "links", ("name", "between", "resistance")):
        between = table["between"]
        if not isinstance(between, list) or len(between) != 2 or not all(isinstance(b, str) for b in between):
            raise _fail(source, f"{entry}.between", "two names: nodes, or a node and a boundary")
        for end in between:
            if end not in nodes and end not in boundaries:
                raise _fail(source, f"{entry}.between", f"a node or boundary of the model, got {end!r} (a link to nothing)")
        if between[0] == between[1] or not (between[0] in nodes or between[1] in nodes):
            raise _fail(source, f"{entry}.between", "two different ends, at least one of them a node")
        resistance = _expression(source, f"{entry}.resistance", table["resistance"])
        for name in resistance.names:
            if name in nodes or name in boundaries:
                raise _fail(source, f"{entry}.resistance", f"parameters and channels only, got the temperature {name!r}")
        out.append(LinkEntry(label, (between[0], between[1]), resistance))
    return tuple(out)


def _capacities(source, prefix, doc, nodes, boundaries) -> tuple[CapacityEntry, ...]:
    out = []
    for i, table in enumerate(_entries(source, f"{prefix}capacities", doc.get("capacities", []))):
        entry = f"{prefix}capacities[{i}]"
        _keys(source, entry, table, ("node", "capacity"), ("node", "capacity"))
        node = table["node"]
        if node not in nodes:
            raise _fail(source, f"{entry}.node", f"a node of the model, got {node!r}")
        capacity = _expression(source, f"{entry}.capacity", table["capacity"])
        for name in capacity.names:
            if name in nodes or name in boundaries:
                raise _fail(source, f"{entry}.capacity", f"parameters and channels only (a temperature as the "
                                                         f"channel that measures it), got the temperature {name!r}")
        if nodes[node] not in capacity.names:
            raise _fail(source, f"{entry}.capacity", f"a law of node {node}'s capacity parameter {nodes[node]} "
                                                     "(its [nodes] entry), which it does not name")
        out.append(CapacityEntry(node, capacity))
    _unique(source, f"{prefix}capacities", [c.node for c in out])
    return tuple(out)


def _sources(source, prefix, doc, nodes, boundaries, params) -> tuple[SourceEntry, ...]:
    out = []
    for label, entry, table in _named_entries(source, prefix, doc, "sources", ("name", "node", "heat")):
        if table["node"] not in nodes:
            raise _fail(source, f"{entry}.node", f"a node of the model, got {table['node']!r}")
        heat = _expression(source, f"{entry}.heat", table["heat"])
        for name in heat.names:
            if name in boundaries:
                raise _fail(source, f"{entry}.heat", f"parameters, channels and node temperatures, got the boundary {name!r}")
        try:
            affine_parts(heat, kinds(params, nodes, heat.names))
        except ExpressionError as exc:
            raise _fail(source, f"{entry}.heat", str(exc)) from None
        out.append(SourceEntry(label, table["node"], heat))
    return tuple(out)


def _outputs(source, entry, table, nodes, params) -> dict[str, str]:
    out = {}
    for channel, node in _table(source, entry, table).items():
        _name(source, f"{entry}.{channel}", channel, "a channel name")
        if node not in nodes:
            raise _fail(source, f"{entry}.{channel}", f"a node of the model, got {node!r} (an output to no state)")
        if channel in nodes or channel in params:
            raise _fail(source, f"{entry}.{channel}", "a channel name no node or parameter shares")
        out[channel] = node
    return out


def _lags(source, prefix, doc, nodes, outputs, params) -> tuple[LagEntry, ...]:
    out = []
    for i, table in enumerate(_entries(source, f"{prefix}lags", doc.get("lags", []))):
        entry = f"{prefix}lags[{i}]"
        _keys(source, entry, table, ("output", "node", "time_constant"), ("output", "node", "time_constant"))
        output, node, tau = table["output"], table["node"], table["time_constant"]
        if output not in outputs:
            raise _fail(source, f"{entry}.output", f"a measured channel of [outputs], got {output!r}")
        if node != outputs[output]:
            raise _fail(source, f"{entry}.node", f"the node [outputs] names for {output} ({outputs[output]!r}), got {node!r}")
        if tau not in params:
            raise _fail(source, f"{entry}.time_constant", f"a parameter name (with a [parameters] table), got {tau!r}")
        _positive(source, entry, params[tau], "a time constant")
        out.append(LagEntry(output, node, tau))
    _unique(source, f"{prefix}lags", [g.output for g in out])
    return tuple(out)


def _calibrations(source, prefix, doc, outputs, params) -> tuple[CalibrationEntry, ...]:
    out = []
    for i, table in enumerate(_entries(source, f"{prefix}calibrations", doc.get("calibrations", []))):
        entry = f"{prefix}calibrations[{i}]"
        _keys(source, entry, table, ("output",) + CALIBRATION_TERMS, ("output",))
        output = table["output"]
        if output not in outputs:
            raise _fail(source, f"{entry}.output", f"a measured channel of [outputs], got {output!r}")
        if not any(term in table for term in CALIBRATION_TERMS):
            raise _fail(source, entry, "at least one of gain, offset, drift (reading = gain * T + offset + drift * t)")
        for term in CALIBRATION_TERMS:
            if term in table and table[term] not in params:
                raise _fail(source, f"{entry}.{term}",
                            f"a parameter name (with a [parameters] table), got {table[term]!r}")
        if "gain" in table:
            _positive(source, entry, params[table["gain"]], "a sensor's gain")
        out.append(CalibrationEntry(output, *(table.get(term) for term in CALIBRATION_TERMS)))
    _unique(source, f"{prefix}calibrations", [c.output for c in out])
    return tuple(out)


def _initial(source, prefix, doc, nodes, outputs, lags, params) -> dict[str, str]:
    given = _table(source, f"{prefix}initial", doc.get("initial", {}))
    states = list(nodes) + [g.output for g in lags]
    for state, channel in given.items():
        if state not in states:
            raise _fail(source, f"{prefix}initial.{state}", f"a node or lagged output of the model, got {state!r}")
        _name(source, f"{prefix}initial.{state}", channel, "a channel")
    out = {}
    measured_by = {}
    for channel, node in outputs.items():
        measured_by.setdefault(node, channel)
    for node in nodes:
        channel = given.get(node, measured_by.get(node))
        if channel is None:
            raise _fail(source, f"{prefix}initial.{node}", "a channel to start this unmeasured node from")
        out[node] = channel
    for lag in lags:
        out[lag.output] = given.get(lag.output, out[lag.node])
    return out


def _unique(source: str, entry: str, names: list[str]) -> None:
    seen = set()
    for name in names:
        if name in seen:
            raise _fail(source, f"{entry}[{name}]", "a name no other entry of the table has")
        seen.add(name)


def kinds(params: Mapping[str, Any], nodes: Mapping[str, Any], names: frozenset[str] | set[str]) -> dict[str, str]:
    """What each name of an expression is: a parameter, a node temperature or (any other name) a run channel."""
    return {n: "parameter" if n in params else "node" if n in nodes else "channel" for n in names}


def _check_names(model: ModelDefinition, prefix: str) -> None:
    """Channel names must not collide with node or boundary names (parameters win in expressions)."""
    taken = set(model.nodes) | set(model.boundaries)
    for channel in model.channels():
        if channel in taken:
            raise _fail(model.source, f"{prefix}{channel}", "a channel name no node or boundary shares")
    for name, param in model.parameters.items():
        used = (name in model.nodes.values() or any(g.time_constant == name for g in model.lags)
                or any(name in c.names for c in model.calibrations)
                or any(name in c.capacity.names for c in model.capacities)
                or any(name in l.resistance.names for l in model.links) or any(name in s.heat.names for s in model.sources))
        if not used:
            raise _fail(model.source, f"{prefix}parameters.{name}", "a parameter the model uses (no law names it)")


def load_model(path: "str | os.PathLike[str]") -> ModelDefinition:
    """Read and check a model file (TOML)."""
    return parse_model(read_document(path, "model file", tomllib.loads, (tomllib.TOMLDecodeError,), "TOML"), path)


def _toml_value(value: object) -> str:
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def _toml_key(key: str) -> str:
    return key if NAME.match(key) else json.dumps(key)


def to_toml(model: ModelDefinition) -> str:
    """The model as a TOML model file (the inverse of load_model: parsing it gives the same model)."""
    doc = model.to_doc()
    lines = [f"{k} = {_toml_value(doc[k])}" for k in ("schema", "name", "description", "requires") if k in doc]
    for table in ("nodes", "boundaries"):
        if table in doc:
            lines += ["", f"[{table}]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in doc[table].items()]
    for array in ("capacities", "links", "sources", "lags", "calibrations"):
        for item in doc.get(array, []):
            lines += ["", f"[[{array}]]"] + [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    for table in ("outputs", "simulated", "initial"):
        if table in doc:
            lines += ["", f"[{table}]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in doc[table].items()]
    for name, table in doc["parameters"].items():
        lines += ["", f"[parameters.{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"
