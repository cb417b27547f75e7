"""A thermal network with parameter values and a state that moves as channels are fed to it, chunk after chunk.

The simulated bench's plant builds on it (sim_bench.plant.ThermalPlant adds effects, μ(ϑ) and the fixed-point
iteration of laws that read its own temperatures); on a hardware bench a parameter file's model stands in for the
clutch where a run's closed-loop steps are timed in advance (protocols.estimates.Plant).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from benchlab.network.sensors import reading
from benchlab.network.solver import DEFAULT_RESOLUTION, run_network
from benchlab.network.stream import NetworkStream
from benchlab.network.structure import Params, ThermalNetwork, sequential_laws


def unplayable(network: ThermalNetwork) -> str | None:
    """Why a plant cannot run `network` chunk by chunk (what a model must be instead), or None where it can: each
    chunk would start a switch with hysteresis afresh."""
    switched = sequential_laws(network)
    if not switched:
        return None
    return (f"a model without hysteresis(...) ({', '.join(switched)} switches: a plant does not carry a switch from "
            "chunk to chunk yet, docs/models.md)")


class NetworkPlant:
    """True temperatures of a network for given channels; keeps its state between calls."""

    def __init__(self, network: ThermalNetwork, params: Params) -> None:
        problem = unplayable(network)
        if problem:
            raise ValueError(problem)
        self.network = network
        self.params = params
        self.state: np.ndarray | None = None
        self._stream: NetworkStream | None = None

    @property
    def state_names(self) -> list[str]:
        return self.network.state_names

    def friction_factor(self, state: np.ndarray | None = None) -> float:
        """μ(ϑ)/μ_cal: the torque the clutch transmits per newton-metre commanded; 1 for a network without
        temperature-dependent friction."""
        return 1.0

    def reset(self, temperature_c: float | Mapping[str, float]) -> None:
        """Start every state (or each named state) at the given temperature."""
        if isinstance(temperature_c, Mapping):
            self.state = np.array([temperature_c[s] for s in self.state_names], dtype=float)
        else:
            self.state = np.full(len(self.state_names), float(temperature_c))

    def advance(self, channels: Mapping[str, np.ndarray], dt: float) -> dict[str, np.ndarray]:
        """True state temperatures at the start of each sample of `channels`; the state moves to their end."""
        states = self._states_from_now(channels, dt)
        self.state = states[-1].copy()
        return {name: states[:-1, i] for i, name in enumerate(self.state_names)}

    def _states_from_now(self, channels: Mapping[str, np.ndarray], dt: float) -> np.ndarray:
        """States (N + 1, n) over `channels` from the current state, which is left as it is."""
        if self.state is None:
            raise RuntimeError("reset() the plant before advancing it")
        return self._run(channels, dt)

    def _run(self, channels: Mapping[str, np.ndarray], dt: float) -> np.ndarray:
        """States (N + 1, n) of one pass from the current state, through the plant's own stream of the network
        (what repeats from pass to pass and chunk to chunk is not computed again), the solver where it cannot."""
        if self._stream is None or self._stream.dt != dt:
            self._stream = NetworkStream(self.network, self.params, dt, DEFAULT_RESOLUTION)
        states = self._stream.run(channels, self.state)
        return states.T if states is not None else run_network(self.network, self.params, channels, dt, self.state)

    def sensor_temperatures(self, true_states: Mapping[str, np.ndarray],
                            seconds: "float | np.ndarray" = 0.0) -> dict[str, np.ndarray]:
        """What the sensors see: measured channel name -> true temperature at the sensor, read through a
        miscalibrated sensor's calibration (the network's `calibrations`; `seconds` since the run's start, the clock
        of its drift); the flywheel node's two PT1000s as T_flywheel_1 and T_flywheel_2 (both the flywheel node where
        the network has one sensor)."""
        calibrations = self.network.calibrations
        seen = {channel: reading(calibrations.get(channel), self.params, true_states[state], seconds)
                for channel, state in self.network.outputs.items()}
        for sensor in ("T_flywheel_1", "T_flywheel_2"):
            seen.setdefault(sensor, seen["T_flywheel"])
        return seen
