"""What a deployed module holds, worked out in Python from the parameter file: its states, inputs, sensors, the
operating-point key, the noise and the wear tables. `benchlab.deploy.csource` writes it as C; `verify` feeds a run
through it. Everything here comes from the homes the Python observer uses (the model's network, its noise tuning,
its operating-point quanta, the clutch file), so the module computes what `OnlineObserver` computes."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from benchlab.errors import InputError
from benchlab.model.definition import kinds
from benchlab.model.params import ModelParams
from benchlab.network import state_channels
from benchlab.network.structure import sequential_laws
from benchlab.observer.noise import NoiseModel, tune_noise
from benchlab.observer.online import WEAR_CHANNELS, quantum_of
from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.thermal import heat_split

#: Range each input is clamped to, by the contract's unit (a value outside is a broken signal, not a clutch);
#: any other unit is held within ±OTHER_LIMIT.
INPUT_RANGE = {"rpm": (-20000.0, 20000.0), "1": (0.0, 1.0), "W": (-1.0e6, 1.0e6), "N*m": (-5000.0, 5000.0),
               "degC": (-60.0, 600.0), "rad/s": (-2500.0, 2500.0)}
OTHER_LIMIT = 1.0e9
#: A reading outside this range (degC) is refused as a broken sensor, like a missing one.
READING_RANGE = (-60.0, 600.0)


@dataclass(frozen=True)
class Plan:
    """The module's content: names, structure, constants (SI units, degC), in the order the C arrays hold them."""

    name: str
    model: str
    dt: float
    params: ModelParams
    states: tuple[str, ...]  # state names of the network (nodes, then sensor lags)
    state_channels: tuple[str, ...]  # each state's channel name (T_pressure_plate, ...)
    inputs: tuple[str, ...]  # the law channels, then one per boundary (its first channel)
    input_units: tuple[str, ...]
    input_sources: tuple[tuple[str, ...], ...]  # per input, the run channels it is read from (the first present)
    boundary_channels: tuple[tuple[str, ...], ...]  # per boundary, the channels it may be read from
    key: tuple[str, ...]  # the inputs that set the operating point (read by resistances and temperature terms)
    sensors: tuple[str, ...]
    noise: NoiseModel
    clutch: ClutchSpec | None  # wear on line where the model has plate, flywheel and friction power
    split: float

    @property
    def n(self) -> int:
        return len(self.states)

    def quantum(self, channel: str) -> float:
        return quantum_of(channel)

    def input_range(self, index: int) -> tuple[float, float]:
        return INPUT_RANGE.get(self.input_units[index], (-OTHER_LIMIT, OTHER_LIMIT))


def module_name(model: str) -> str:
    """A C identifier from the model's name: `clutch-nonlinear` -> `clutch_nonlinear`."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", model).strip("_").lower() or "model"
    return name if not name[0].isdigit() else "m_" + name


def make_plan(params: ModelParams, sensors: Sequence[str], dt: float, clutch: ClutchSpec | None,
              source: str = "--sensors") -> Plan:
    """The plan of one module: the parameter file's model observed with `sensors` at a sample time of `dt` s."""
    from benchlab.runfile import ALIGNED_UNITS

    model = params.definition
    network = params.network
    switched = sequential_laws(network)
    if switched:
        raise InputError(params.definition.source, ", ".join(switched), "a law without hysteresis(...): the deployed C module "
                         "does not carry a switch's state yet (docs/deploy.md)")
    if model.capacities:
        raise InputError(model.source, f"capacities[{model.capacities[0].node}]", "a model whose capacities are "
                         "parameters: the deployed C module holds each capacity constant (docs/deploy.md)")
    names = state_channels(network)
    for channel in sensors:
        if channel not in network.outputs:
            raise InputError(source, channel, f"a channel the model predicts ({', '.join(sorted(network.outputs))})")
    law_inputs: list[str] = []
    key: list[str] = []
    for expr in [l.resistance for l in model.links] + [s.heat for s in model.sources]:
        read = kinds(model.parameters, model.nodes, expr.names)
        channels = [c for c in sorted(expr.names) if read[c] == "channel"]
        law_inputs += [c for c in channels if c not in law_inputs]
        temperature_term = any(read[c] == "node" for c in expr.names)
        if expr in [l.resistance for l in model.links] or temperature_term:
            key += [c for c in channels if c not in key]
    boundaries = tuple(tuple(channels) for channels in model.boundaries.values())
    sources = {c: (c,) for c in law_inputs}
    for channels in boundaries:
        sources.setdefault(channels[0], channels)
    inputs = list(sources)
    states = tuple(network.state_names)
    wear_ready = (WEAR_CHANNELS[0] in names.values() and WEAR_CHANNELS[1] in names.values()
                  and WEAR_CHANNELS[2] in inputs)
    return Plan(module_name(model.name), params.model, float(dt), params, states,
                tuple(names[s] for s in states), tuple(inputs), tuple(ALIGNED_UNITS.get(c, "") for c in inputs),
                tuple(sources.values()), boundaries, tuple(key), tuple(dict.fromkeys(sensors)), tune_noise(network, params, list(sensors)),
                clutch if wear_ready else None, heat_split(params))
