"""Lumped thermal network: nodes with capacities, links with resistances, heat sources, boundaries.

The paper's clutch (eq. 6-9) is one such network. A model extension is an edit of the
network (a link whose resistance depends on a channel, a new source, a new node, a sensor
lag), so the solver never changes when the physics does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from benchlab.network.sensors import Calibration

Params = Mapping[str, float]
Channels = Mapping[str, np.ndarray]
#: A resistance (K/W) or heat flow (W): a scalar, or one value per sample, from params and channels.
ParamChannelFunction = Callable[[Params, Channels], "float | np.ndarray"]


@dataclass(frozen=True)
class Node:
    """A lumped thermal mass whose temperature is a model state.

    `capacity_law`: where the capacity varies (with the node's own temperature, read from its measurement), its value
    in J/K from params and channels; the state then follows dϑ/dt = Q/C (the heat stored is ∫C dϑ), and the solver
    holds C per step as it holds a link's resistance. None: the capacity is the parameter `capacity`."""

    name: str
    capacity: str  # parameter name of the heat capacity in J/K (where a law is given, the one it scales)
    capacity_law: "ParamChannelFunction | None" = None


@dataclass(frozen=True)
class Boundary:
    """A temperature imposed from outside (engine, ambient), taken from measured channels."""

    name: str
    temperature: Callable[[Channels], np.ndarray]


@dataclass(frozen=True)
class Link:
    """Heat conduction or convection between two nodes (or a node and a boundary)."""

    a: str
    b: str
    resistance: ParamChannelFunction
    label: str = ""


@dataclass(frozen=True)
class Source:
    """Heat flow in W injected into one node: `heat_flow` plus, where it is affine in node temperatures,
    Σ coefficient·ϑ_node (W/K each), which the solver puts into the state matrix."""

    node: str
    heat_flow: ParamChannelFunction
    label: str = ""
    coefficients: tuple[tuple[str, ParamChannelFunction], ...] = ()


@dataclass(frozen=True)
class Lag:
    """A first-order sensor: a state that follows `node` with time constant parameter `time_constant`."""

    name: str
    node: str
    time_constant: str  # parameter name, seconds


@dataclass(frozen=True)
class ThermalNetwork:
    """The whole model structure; parameters are supplied separately as a name -> value map."""

    nodes: tuple[Node, ...]
    boundaries: tuple[Boundary, ...]
    links: tuple[Link, ...]
    sources: tuple[Source, ...]
    outputs: Mapping[str, str]  # measured/simulated channel name -> state name
    lags: tuple[Lag, ...] = ()
    initial: Mapping[str, str] = field(default_factory=dict)  # state -> channel it starts from
    measured: tuple[str, ...] = ()  # the outputs a run measures (fitted and scored); the rest are only simulated
    #: measured channel -> its sensor's calibration (benchlab.network.sensors: the output equation); absent: it
    #: reads its state as it is
    calibrations: Mapping[str, Calibration] = field(default_factory=dict)

    @property
    def state_names(self) -> list[str]:
        return [n.name for n in self.nodes] + [lag.name for lag in self.lags]

    def with_link(self, link: Link) -> "ThermalNetwork":
        return replace(self, links=self.links + (link,))

    def replace_links(self, keep: Callable[[Link], bool], new: tuple[Link, ...]) -> "ThermalNetwork":
        return replace(self, links=tuple(l for l in self.links if keep(l)) + new)

    def with_source(self, source: Source) -> "ThermalNetwork":
        return replace(self, sources=self.sources + (source,))

    def with_node(self, node: Node, initial_from: str) -> "ThermalNetwork":
        return replace(self, nodes=self.nodes + (node,), initial={**self.initial, node.name: initial_from})

    def with_lag(self, lag: Lag, output: str) -> "ThermalNetwork":
        """Add a sensor lag and route the measured channel `output` through it."""
        return replace(self, lags=self.lags + (lag,), outputs={**self.outputs, output: lag.name},
                       initial={**self.initial, lag.name: self.initial.get(lag.node, output)})

    def validate(self) -> None:
        """Raise ValueError for links or outputs that name unknown nodes."""
        known = set(self.state_names) | {b.name for b in self.boundaries}
        for link in self.links:
            for end in (link.a, link.b):
                if end not in known:
                    raise ValueError(f"link {link.label or (link.a, link.b)} names unknown node {end!r}")
        for src in self.sources:
            for node in (src.node, *(name for name, _ in src.coefficients)):
                if node not in {n.name for n in self.nodes}:
                    raise ValueError(f"source {src.label} names unknown node {node!r}")
        for channel, state in self.outputs.items():
            if state not in self.state_names:
                raise ValueError(f"output {channel} reads unknown state {state!r}")
        for channel in self.calibrations:
            if channel not in self.outputs:
                raise ValueError(f"calibration of {channel}, which is no output")


def sequential_laws(network: ThermalNetwork) -> list[str]:
    """The links, sources and capacities whose law at a sample depends on the samples before it (a switch with
    hysteresis, benchlab.network.switching): a run's laws are then evaluated over the whole run, never a part of it alone."""
    laws = [(link.label or f"{link.a}-{link.b}", link.resistance) for link in network.links]
    laws += [(src.label or src.node, src.heat_flow) for src in network.sources]
    laws += [(src.label or src.node, law) for src in network.sources for _, law in src.coefficients]
    laws += [(f"capacity of {node.name}", node.capacity_law) for node in network.nodes if node.capacity_law]
    return list(dict.fromkeys(name for name, law in laws if getattr(law, "sequential", False)))


def as_samples(value: "float | np.ndarray", n: int) -> np.ndarray:
    """Broadcast a scalar-or-array law result to one float64 value per sample."""
    arr = np.asarray(value, dtype=np.float64)
    return np.broadcast_to(arr, (n,)) if arr.ndim == 0 else arr


def sample_matrix(columns: "list[np.ndarray]", n: int) -> np.ndarray:
    """Per-sample columns side by side: a C-ordered (n, columns) matrix, (n, 0) for none (the compiled kernels take
    one layout)."""
    return np.ascontiguousarray(np.stack(columns, axis=1)) if columns else np.zeros((n, 0))


def state_channels(network: ThermalNetwork) -> dict[str, str]:
    """Each state's channel name for files and figures: the first output that reads it, else the state's own name.

    The clutch's P, F, A, T become T_pressure_plate, T_flywheel, T_air, T_housing (the /simulated names).
    """
    names = {}
    for channel, state in network.outputs.items():
        names.setdefault(state, channel)
    return {state: names.get(state, state) for state in network.state_names}
