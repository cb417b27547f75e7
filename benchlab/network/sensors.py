"""The output equation: what a calibrated sensor reads of its state, and the state a reading stands for.

A measured channel reads its state (a node, or a sensor lag's state) as `gain * T + offset + drift * t`, t the
seconds since the run's first sample (contract §6, `[[calibrations]]`). Every user of a model's outputs goes
through this module: the simulation's output stage, identification's residuals and initial states, the cool-down
analysis, the observers, wear's lining temperatures, the deployed C module (`coefficients`) and the simulated
plant's readings, so the equation has one home.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Calibration:
    """The parameter names of one output's calibration (None: gain 1, offset 0 K, drift 0 K/s)."""

    gain: str | None = None  # 1 (dimensionless)
    offset: str | None = None  # K
    drift: str | None = None  # K/s

    def values(self, params: Mapping[str, float]) -> tuple[float, float, float]:
        """(gain, offset K, drift K/s) at the given parameter values."""
        return (float(params[self.gain]) if self.gain else 1.0, float(params[self.offset]) if self.offset else 0.0,
                float(params[self.drift]) if self.drift else 0.0)

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters it reads."""
        return tuple(n for n in (self.gain, self.offset, self.drift) if n)


def reading(calibration: Calibration | None, params: Mapping[str, float], temperature: "float | np.ndarray",
            seconds: "float | np.ndarray") -> "float | np.ndarray":
    """What the sensor reads of its state's temperature at `seconds` since the run's first sample."""
    if calibration is None:
        return temperature
    gain, offset, drift = calibration.values(params)
    return gain * temperature + offset + drift * seconds if drift else gain * temperature + offset


def temperature_of(calibration: Calibration | None, params: Mapping[str, float], value: "float | np.ndarray",
                   seconds: "float | np.ndarray") -> "float | np.ndarray":
    """The state's temperature a reading stands for (the inverse of `reading`): a state started from its channel, a
    reading handed to the observer."""
    if calibration is None:
        return value
    gain, offset, drift = calibration.values(params)
    return (value - offset - drift * seconds) / gain


def coefficients(calibration: Calibration | None, params: Mapping[str, float]) -> tuple[float, float, float]:
    """(gain, offset K, drift K/s) of an output, (1, 0, 0) where it has no calibration: the numbers the online
    observer and the deployed C module invert a reading with."""
    return (1.0, 0.0, 0.0) if calibration is None else calibration.values(params)
