"""A checked model file made runnable: its thermal network (benchlab.network) and what identification fits.

Expressions are compiled once here; links with the same resistance text share one compiled law, so the
solver evaluates it once and keys the operating points once (R_PA = R_FA of the paper's clutch).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from benchlab.identify.spec import ModelSpec, ParamSpec
from benchlab.model.definition import ModelDefinition, kinds
from benchlab.model.expressions import Expression, affine_parts, compile_expression
from benchlab.network import Boundary, Calibration, Channels, Lag, Link, Node, Params, Source, ThermalNetwork

NO_TEMPERATURES: dict[str, float] = {}


def _law(compiled: Callable, reads: frozenset[str], sequential: bool = False) -> Callable[[Params, Channels],
                                                                                     "float | np.ndarray"]:
    """A law of params and channels; `reads`: the parameters it reads (its value changes with nothing else on one
    run's channels, which lets a fit's solver memo keep it: benchlab.network.memo); `sequential`: its value at a
    sample depends on the samples before it (a switch with hysteresis: benchlab.network.structure.sequential_laws)."""
    def law(params: Params, channels: Channels) -> "float | np.ndarray":
        return compiled(params, channels, NO_TEMPERATURES)
    law.reads = tuple(sorted(reads))
    law.sequential = sequential
    return law


def _parameters_read(model: ModelDefinition, expr: Expression) -> frozenset[str]:
    return frozenset(name for name, kind in kinds(model.parameters, model.nodes, expr.names).items()
                     if kind == "parameter")


def _first_present(channels: tuple[str, ...]) -> Callable[[Channels], np.ndarray]:
    """A boundary's temperature: the first of its channels the run holds with at least one valid sample."""
    def temperature(values: Channels) -> np.ndarray:
        for name in channels[:-1]:
            if name in values and not np.all(np.isnan(values[name])):
                return values[name]
        return values[channels[-1]]
    temperature.reads = ()  # no parameter: one value per run's channels (benchlab.network.memo)
    return temperature


def build_network(model: ModelDefinition) -> ThermalNetwork:
    """The model's nodes (with their capacity laws), boundaries, links, sources, sensor lags and calibrations as a
    ThermalNetwork."""
    laws: dict[str, Callable] = {}

    def law(expr: Expression) -> Callable:
        if expr.text not in laws:
            laws[expr.text] = _law(compile_expression(expr, kinds(model.parameters, model.nodes, expr.names)),
                                   _parameters_read(model, expr), expr.sequential)
        return laws[expr.text]

    sources = []
    for entry in model.sources:
        constant, coefficients = affine_parts(entry.heat, kinds(model.parameters, model.nodes, entry.heat.names))
        reads = _parameters_read(model, entry.heat)
        sources.append(Source(entry.node, _law(constant, reads, entry.heat.sequential), entry.name,
                              tuple((node, _law(k, reads, entry.heat.sequential)) for node, k in coefficients.items())))
    # a law object of its own (not shared by text with a link's): the solver's memo keeps a link's 1/R under its law
    capacity_laws = {entry.node: _law(compile_expression(entry.capacity, kinds(model.parameters, model.nodes,
                                                                               entry.capacity.names)),
                                      _parameters_read(model, entry.capacity), entry.capacity.sequential)
                     for entry in model.capacities}
    outputs = {**model.simulated, **model.outputs}
    for lag in model.lags:
        outputs[lag.output] = model.lag_state(lag.output)
    return ThermalNetwork(
        nodes=tuple(Node(name, capacity, capacity_laws.get(name)) for name, capacity in model.nodes.items()),
        boundaries=tuple(Boundary(name, _first_present(channels)) for name, channels in model.boundaries.items()),
        links=tuple(Link(l.between[0], l.between[1], law(l.resistance), l.name) for l in model.links),
        sources=tuple(sources),
        outputs=outputs,
        lags=tuple(Lag(model.lag_state(g.output), g.node, g.time_constant) for g in model.lags),
        initial=dict(model.initial),
        measured=tuple(model.outputs),
        calibrations={c.output: Calibration(c.gain, c.offset, c.drift) for c in model.calibrations},
    )


def build_spec(model: ModelDefinition) -> ModelSpec:
    """The network with its free parameters and fixed values. A parameter is fitted on a log scale where its lower
    bound is positive and the file gives no `scale`, else linearly in steps of `scale` (default |start|)."""
    free = tuple(ParamSpec(p.name, p.start, p.min, p.max, log=p.min > 0 and p.scale is None, unit=p.unit,
                           scale=p.scale or 0.0)
                 for p in model.free_parameters())
    fixed = {p.name: p.fixed for p in model.parameters.values() if p.fixed is not None}
    return ModelSpec(model.label, build_network(model), free, fixed, model)
