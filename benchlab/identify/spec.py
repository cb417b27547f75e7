"""What is identified: a network plus its free parameters with physical bounds and neutral starting values.

Starting values are order-of-magnitude priors for a passenger-car dry clutch, not any
particular bench's answer; multi-start spreads them by a factor of a few either way.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from benchlab.clutch import clutch_network
from benchlab.network import ThermalNetwork


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
    """A model to fit: its network, its free parameters, and values held fixed."""

    name: str
    network: ThermalNetwork
    free: tuple[ParamSpec, ...]
    fixed: Mapping[str, float] = field(default_factory=dict)

    def with_fixed(self, values: Mapping[str, float]) -> "ModelSpec":
        """Hold the named parameters at the given values (`--fix C_T=12000`)."""
        return replace(self, free=tuple(p for p in self.free if p.name not in values),
                       fixed={**self.fixed, **values})

    def extended(self, name: str, network: ThermalNetwork, extra: tuple[ParamSpec, ...],
                 fixed: Mapping[str, float] | None = None) -> "ModelSpec":
        """A new spec with an edited network and additional free (and fixed) parameters."""
        return ModelSpec(name, network, self.free + extra, {**self.fixed, **dict(fixed or {})})

    def starting_point(self, values: Mapping[str, float]) -> "ModelSpec":
        """Same spec, starting from the given values where it names them (a warm start)."""
        return replace(self, free=tuple(replace(p, initial=min(max(values.get(p.name, p.initial), p.lower), p.upper))
                                        for p in self.free))


CAPACITY = dict(lower=20.0, upper=2e5, unit="J/K")
RESISTANCE = dict(lower=1e-3, upper=50.0, unit="K/W")
LINEAR_FREE = (
    ParamSpec("C_P", 1000.0, **CAPACITY), ParamSpec("C_F", 5000.0, **CAPACITY),
    ParamSpec("C_A", 1000.0, **CAPACITY), ParamSpec("C_T", 10000.0, **CAPACITY),
    ParamSpec("R_AT", 0.1, **RESISTANCE), ParamSpec("R_Feng", 1.0, **RESISTANCE),
    ParamSpec("R_Tamb", 0.2, **RESISTANCE), ParamSpec("R0", 0.3, **RESISTANCE),
)
CONVECTION_FREE = (
    ParamSpec("a1", 0.3, 1e-4, 20.0, unit="K/W"), ParamSpec("b1", -1e-3, -1e-2, -1e-5, log=False, unit="1/rpm"),
    ParamSpec("a2", 0.3, 1e-4, 20.0, unit="K/W"), ParamSpec("b2", -1e-3, -1e-2, -1e-5, log=False, unit="1/rpm"),
)


def clutch_spec(model: str) -> ModelSpec:
    """The paper's clutch, linear (constant convection R0) or nonlinear (eq. 11)."""
    if model == "linear":
        return ModelSpec("linear", clutch_network(), LINEAR_FREE, {"a1": 0.0, "b1": 0.0, "a2": 0.0, "b2": 0.0})
    if model == "nonlinear":
        return ModelSpec("nonlinear", clutch_network(), LINEAR_FREE + CONVECTION_FREE)
    raise ValueError(f"unknown model {model!r}")
