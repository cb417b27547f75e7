"""What runs would identify a parameter, read from the model file: where it enters (a node's capacity, a sensor's
lag, a link's resistance, a heat flow), on which channels that law depends and under which of its `where`
conditions the parameter counts.

`not_identified` (benchlab.identify.identifiability) adds this to each reason, so that "not identified" says what
to measure next: for the paper's clutch, a2 of eq. (11) asks for long cool-downs at several engine speeds with
the clutch open, which `benchlab run cooldown-sweep` gives.
"""

from __future__ import annotations

import ast

import numpy as np

from benchlab.model.definition import ModelDefinition, kinds
from benchlab.model.expressions import Expression, compile_expression, parse
from benchlab.runfile.schema import ALIGNED_LEVELS, ALIGNED_UNITS
from protocols.catalog import COOLDOWNS_AT

#: A `where` condition that does not hold, said as the comparison that does.
_NEGATED = {ast.Lt: ">=", ast.LtE: ">", ast.Gt: "<=", ast.GtE: "<", ast.Eq: "!="}

Conditions = tuple[tuple[ast.expr, bool], ...]


def what_identifies(model: ModelDefinition, name: str) -> str:
    """The runs or the measurement that would identify parameter `name` of `model`, in words ("" for a name the
    model's laws do not hold)."""
    needs: list[str] = []
    for node, capacity in model.nodes.items():
        if capacity == name:
            needs.append(f"faster heat-ups and cool-downs of node {node}" if node in model.outputs.values() else
                         f"a temperature sensor on node {node} (nothing measures it: its capacity shows only through "
                         "the measured temperatures)")
    for entry in model.capacities:
        if name in entry.capacity.names and name != model.nodes[entry.node]:
            needs.append(f"heat-ups and cool-downs of node {entry.node} over a wide range of "
                         f"{', '.join(_channels(model, entry.capacity.tree)) or 'its temperature'}")
    needs += [f"changes of {lag.output} faster than its sensor follows" for lag in model.lags
              if lag.time_constant == name]
    for link in model.links:
        for conditions, channels in _occurrences(model, link.resistance, name):
            needs.append(_cooldowns(model, conditions, channels))
    for source in model.sources:
        for conditions, channels in _occurrences(model, source.heat, name):
            varied = f" at several values of {', '.join(channels)}" if channels else ""
            needs.append(f"runs that vary the heat flow '{source.name}' into node {source.node}{varied}"
                         f"{_when(model, conditions)}")
    return "; or ".join(dict.fromkeys(needs))


def _cooldowns(model: ModelDefinition, conditions: Conditions, channels: list[str]) -> str:
    """A link's law: long cool-downs (the heat sources off, the heat flowing through the links) where it counts, and
    the bench's protocol that runs them where the model is of the bench's channels and one holds the law's channels
    at several values."""
    read = set(channels) | {c for cond, _ in conditions for c in _channels(model, cond)}
    on_the_bench = model.law_channels() <= set(ALIGNED_UNITS)
    protocols = [p for p, held in COOLDOWNS_AT.items() if on_the_bench and read <= set(held)]
    varied = f" at several values of {', '.join(channels)}" if channels else ""
    runs = f" (benchlab run {protocols[0]})" if protocols else ""
    return f"runs with long cool-downs{varied}{_when(model, conditions)}{runs}"


def _occurrences(model: ModelDefinition, law: Expression, name: str) -> list[tuple[Conditions, list[str]]]:
    """Where `name` enters a law: the `where` conditions on the way to it and the channels of the additive term
    that holds it (what must vary for its effect to show), once per distinct pair."""
    found = _walk(law.tree, name, (), law.tree)
    out = {}
    for conditions, term in found:
        channels = sorted(set(_channels(model, term)) - {c for cond, _ in conditions for c in _channels(model, cond)})
        out[(tuple((ast.dump(c), truth) for c, truth in conditions), tuple(channels))] = (conditions, channels)
    return list(out.values())


def _walk(node: ast.AST, name: str, conditions: Conditions, term: ast.expr) -> list[tuple[Conditions, ast.expr]]:
    if isinstance(node, ast.Name):
        return [(conditions, term)] if node.id == name else []
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        return _walk(node.left, name, conditions, node.left) + _walk(node.right, name, conditions, node.right)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "where":
        cond, yes, no = node.args
        return (_walk(cond, name, conditions, term) + _walk(yes, name, conditions + ((cond, True),), yes)
                + _walk(no, name, conditions + ((cond, False),), no))
    return [found for child in ast.iter_child_nodes(node) if isinstance(child, ast.expr)
            for found in _walk(child, name, conditions, term)]


def _channels(model: ModelDefinition, node: ast.AST) -> list[str]:
    """The run channels an expression reads (the calls' function names are no names of it)."""
    called = {id(n.func) for n in ast.walk(node) if isinstance(n, ast.Call)}
    names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and id(n) not in called}
    return sorted(n for n, kind in kinds(model.parameters, model.nodes, names).items() if kind == "channel")


def _when(model: ModelDefinition, conditions: Conditions) -> str:
    """" with ..." for the conditions under which a term counts ("" for none)."""
    said = [_condition(model, cond, truth) for cond, truth in conditions]
    return f" with {' and '.join(said)}" if said else ""


def _condition(model: ModelDefinition, cond: ast.expr, truth: bool) -> str:
    """A condition as words: by the states of a channel that has named states (clutch_state: the clutch open),
    else as the comparison that holds."""
    channels = _channels(model, cond)
    if len(channels) == 1 and channels[0] in ALIGNED_LEVELS:
        levels = ALIGNED_LEVELS[channels[0]]
        compiled = compile_expression(parse(ast.unparse(cond)), kinds(model.parameters, model.nodes,
                                                                      {n.id for n in ast.walk(cond)
                                                                       if isinstance(n, ast.Name)}))
        starts = {k: p.start for k, p in model.parameters.items()}
        holding = [words for level, words in levels.items()
                   if bool(np.asarray(compiled(starts, {channels[0]: np.float64(level)}, {}))) == truth]
        if holding:
            return " or ".join(holding)
    text = ast.unparse(cond)
    if truth:
        return text
    if isinstance(cond, ast.Compare) and len(cond.ops) == 1:
        return f"{ast.unparse(cond.left)} {_NEGATED[type(cond.ops[0])]} {ast.unparse(cond.comparators[0])}"
    return f"not ({text})"
