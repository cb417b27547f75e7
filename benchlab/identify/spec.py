"""What is identified: a network plus its free parameters with physical bounds and starting values.

Bounds and starting values come from the model file (benchlab.model); multi-start spreads the starts
by a factor of a few either way.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from benchlab.network import ThermalNetwork

if TYPE_CHECKING:
    from benchlab.model.definition import ModelDefinition


@dataclass(frozen=True)
class ParamSpec:
    """A free parameter: start value, bounds, and whether it is fitted on a log scale (positive quantities)."""

    name: str
    initial: float
    lower: float
    upper: float
    log: bool = True
    unit: str = ""
    scale: float = 0.0  # for signed parameters: the step of one unit of the fitted coordinate (default |initial|)

    @property
    def linear_scale(self) -> float:
        return self.scale or abs(self.initial) or 1.0


@dataclass(frozen=True)
class ModelSpec:
    """A model to fit: its network, its free parameters, and values held fixed; `definition` is the model file
    it was built from (None for a network built in Python, such as the simulated bench's plant)."""

    name: str
    network: ThermalNetwork
    free: tuple[ParamSpec, ...]
    fixed: Mapping[str, float] = field(default_factory=dict)
    definition: "ModelDefinition | None" = None
    per_group: tuple[str, ...] = ()  # parameters fitted once per run group (`X@<group>`, see split_per_group)

    def with_fixed(self, values: Mapping[str, float]) -> "ModelSpec":
        """Hold the named parameters at the given values (`--fix C_T=12000`)."""
        return replace(self, free=tuple(p for p in self.free if p.name not in values),
                       fixed={**self.fixed, **values})

    def with_free(self, extra: tuple[ParamSpec, ...]) -> "ModelSpec":
        """The same model with additional free parameters (per-run start temperatures)."""
        return replace(self, free=self.free + extra)

    def split_per_group(self, names: tuple[str, ...], groups: tuple[str, ...]) -> "ModelSpec":
        """The same model with each free parameter in `names` fitted once per run group (`X@<group>`, same bounds and
        start; benchlab.identify.fit.run_values applies them): the runs are allowed to disagree on it. X itself stays
        at its start value, which no run then uses."""
        split = [p for p in self.free if p.name in names and p.name not in self.per_group]
        if not split:
            return self
        extra = tuple(replace(p, name=f"{p.name}@{g}") for p in split for g in groups)
        return replace(self, free=tuple(p for p in self.free if p not in split) + extra,
                       fixed={**self.fixed, **{p.name: p.initial for p in split}},
                       per_group=self.per_group + tuple(p.name for p in split))

    def starting_point(self, values: Mapping[str, float]) -> "ModelSpec":
        """Same spec, starting from the given values where it names them (a warm start)."""
        return replace(self, free=tuple(replace(p, initial=min(max(values.get(p.name, p.initial), p.lower), p.upper))
                                        for p in self.free))
