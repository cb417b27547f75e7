"""What the serial emulators measure: provider interfaces and stand-alone defaults.

A thermal plant plugs in by implementing `ResistanceProvider` (wired PT1000 on the DMM) and
`NodeInputProvider` (flywheel node); `TemperatureResistances` turns temperatures into PT1000 resistances.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from drivers import cvd


class ResistanceProvider(Protocol):
    """Resistances the scanning DMM sees now: channel → Ω (inf or NaN = open sensor; missing = open)."""

    def get_resistances(self) -> Mapping[int, float]: ...


@dataclass(frozen=True, slots=True)
class NodeInputs:
    """What the flywheel node measures at one instant: two PT1000 resistances (Ω; inf/NaN = open), supply, radio."""

    resistances_ohm: tuple[float, float]
    supply_mv: int = 5000
    rssi_dbm: int = -60
    lqi: int = 200


@dataclass(frozen=True, slots=True)
class NodeInputSeries:
    """What the flywheel node measures at each of n instants, as columns: resistances (n, 2) Ω (inf/NaN = open);
    supply, RSSI and LQI one per instant or one for all."""

    resistances_ohm: np.ndarray
    supply_mv: "np.ndarray | int" = 5000
    rssi_dbm: "np.ndarray | int" = -60
    lqi: "np.ndarray | int" = 200


class NodeInputProvider(Protocol):
    """The flywheel node's inputs at each of the simulated times `times` (seconds, increasing), in one call."""

    def node_inputs_at(self, times: np.ndarray) -> NodeInputSeries: ...


@dataclass(slots=True)
class ConstantResistances:
    """A fixed channel → Ω table (default: four channels at about 25 °C); edit `values` to inject faults."""

    values: dict[int, float] = field(default_factory=lambda: {ch: 1097.347 for ch in (101, 102, 103, 104)})

    def get_resistances(self) -> Mapping[int, float]:
        return self.values


@dataclass(slots=True)
class TemperatureResistances:
    """Adapter: a `() -> {channel: °C}` source seen through ideal (or calibrated) PT1000 sensors."""

    temperatures: Callable[[], Mapping[int, float]]
    coefficients: Mapping[int, cvd.CvdCoefficients] = field(default_factory=dict)

    def get_resistances(self) -> Mapping[int, float]:
        return {ch: float(cvd.resistance(t, self.coefficients.get(ch, cvd.PT1000)))
                for ch, t in self.temperatures().items()}


@dataclass(slots=True)
class ConstantNodeInputs:
    """Fixed node inputs (default: both sensors at about 25 °C, healthy supply and link)."""

    inputs: NodeInputs = NodeInputs((1097.347, 1097.347))

    def node_inputs_at(self, times: np.ndarray) -> NodeInputSeries:
        i = self.inputs
        return NodeInputSeries(np.broadcast_to(np.array(i.resistances_ohm, dtype=float), (len(times), 2)),
                               i.supply_mv, i.rssi_dbm, i.lqi)
