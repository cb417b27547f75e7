"""A schedule on the simulated bench straight to an aligned run, without the wire-level stack.

Same drivetrain and thermal plant as the emulated bench, same sensor behaviour (noise,
quantisation, sample-and-hold at each device's period, radio drop-outs as NaN gaps), but
computed in whole arrays: hours of bench time in a fraction of a second, for identification
and diagnosis tests at many seeds and magnitudes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchlab.drivetrain import DrivetrainFacts, friction_power, slipping_by_speed
from benchlab.runfile.schema import SCHEMA
from protocols.schedule import Step, setpoints
from sim_bench.drivetrain import CHANNELS, Drivetrain
from sim_bench.plant import ThermalPlant



@dataclass(frozen=True)
class SensorConfig:
    """Noise (1 sigma), resolution and sample periods of the bench's sensors; drop-outs of the radio link."""

    wired_noise_k: float = 0.03
    wired_period_s: float = 0.1
    node_noise_k: float = 0.08
    node_period_s: float = 0.05
    quantum_k: float = 0.01
    speed_noise_rpm: float = 1.0
    torque_noise_nm: float = 0.2
    dropouts_per_hour: float = 20.0
    dropout_mean_s: float = 2.0


@dataclass(frozen=True)
class AmbientConfig:
    """Ambient temperature: mean plus a slow sinusoidal drift."""

    mean_c: float = 22.0
    drift_k: float = 0.5
    period_s: float = 5400.0


def drive_schedule(steps: Sequence[Step], dt: float, config: DrivetrainFacts = DrivetrainFacts(),
                   ) -> tuple[dict[str, np.ndarray], list[dict[str, object]]]:
    """True drivetrain channels over the schedule, plus events (step starts, launch outcomes).

    Open loop only: a step that ends on a condition or heats in pulses needs the temperatures as it
    runs, which the closed-loop bench (`benchlab.runner.session.execute`) provides.
    """
    closed = [s for s in steps if s.until or s.phase == "heat"]
    if closed:
        raise ValueError(f"run_schedule plays open-loop schedules only; step {closed[0].label or closed[0].phase!r} "
                         f"of cycle {closed[0].cycle} ends on a condition or heats in pulses: run the protocol "
                         "through benchlab.runner.session.execute (benchlab run) instead")
    drivetrain = Drivetrain(config, engine_rpm=steps[0].engine_speed_rpm if steps else 0.0)
    pieces: list[dict[str, np.ndarray]] = []
    events: list[dict[str, object]] = []
    t = 0
    stalled_cycle = None
    for step in steps:
        n = int(round(step.duration_s / dt))
        sp = setpoints(step, synchronised=step.cycle != stalled_cycle)
        drivetrain.set_points(sp.engine_speed_rpm, not sp.clutch_open, sp.clutch_torque_nm, sp.load_torque_nm)
        events.append({"time": t * dt, "event": f"{step.phase}_start", "cycle": step.cycle})
        piece = drivetrain.advance(n, dt, stop_at_sync=step.phase == "launch")
        pieces.append(piece)
        t += len(piece["engine_speed"])
        if step.phase == "launch":
            synced = not drivetrain.slipping
            stalled_cycle = None if synced else step.cycle  # the slip-time limit opens the clutch
            events.append({"time": t * dt, "event": "synchronised" if synced else "slip_time_limit",
                           "cycle": step.cycle})
    return {name: np.concatenate([p[name] for p in pieces]) for name in CHANNELS}, events


def _held_readings(values: np.ndarray, period: int, rng: np.random.Generator, noise: float,
                   quantum: float) -> np.ndarray:
    """Sample every `period` steps with noise and quantisation, and hold each reading until the next."""
    picks = values[::period] + rng.normal(0.0, noise, size=len(values[::period]))
    if quantum > 0:
        picks = np.round(picks / quantum) * quantum
    return np.repeat(picks, period)[: len(values)]


def _dropout_mask(n: int, dt: float, sensors: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    mask = np.zeros(n, dtype=bool)
    expected = sensors.dropouts_per_hour * n * dt / 3600.0
    for _ in range(rng.poisson(expected)):
        start = rng.integers(0, n)
        length = max(1, int(rng.exponential(sensors.dropout_mean_s) / dt))
        mask[start:start + length] = True
    return mask


def run_schedule(steps: Sequence[Step], plant: ThermalPlant, seed: int, dt: float = 0.01,
                 sensors: SensorConfig = SensorConfig(), ambient: AmbientConfig = AmbientConfig(),
                 initial_c: float | None = None,
                 engine_c: Callable[[np.ndarray], np.ndarray] | None = None) -> pd.DataFrame:
    """Aligned channels of the contract's /aligned group for the schedule; attrs carry dt, events and truth.

    `engine_c`: the engine side's temperature (degC) against time (s), where the bench has one (an engine-side
    heater): the plant's engine boundary reads it and the run records it as `T_engine`, wired like `T_air`."""
    rng = np.random.default_rng(seed)
    truth, events = drive_schedule(steps, dt)
    n = len(truth["engine_speed"])
    time = np.arange(n) * dt
    truth["T_ambient"] = ambient.mean_c + ambient.drift_k * np.sin(2 * np.pi * time / ambient.period_s)
    if engine_c is not None:
        truth["T_engine"] = np.asarray(engine_c(time), dtype=np.float64)
    plant.reset(truth["T_ambient"][0] if initial_c is None else initial_c)
    states = plant.advance(truth, dt)
    at_sensor = plant.sensor_temperatures(states, time)

    wired = max(1, int(round(sensors.wired_period_s / dt)))
    node = max(1, int(round(sensors.node_period_s / dt)))
    out: dict[str, np.ndarray] = {"time": time}
    out["engine_speed"] = truth["engine_speed"] + rng.normal(0, sensors.speed_noise_rpm, n)
    # a shaft that stands reads 0 (a pulse sensor counts no pulses): noise clipped at 0 rpm would read it ~0.4 rpm too
    # fast while a launch starts, the slip and friction power too low (the bias issue 32's coverage study traced in C_F)
    moving = truth["clutch_speed"] > 0
    out["clutch_speed"] = np.where(moving, np.maximum(truth["clutch_speed"] + rng.normal(0, sensors.speed_noise_rpm, n),
                                                      0.0), 0.0)
    out["clutch_torque"] = truth["clutch_torque"] + rng.normal(0, sensors.torque_noise_nm, n)
    out["clutch_state"] = truth["clutch_state"].copy()
    slipping = ((out["clutch_state"] > 0.5) & slipping_by_speed(out["engine_speed"], out["clutch_speed"])
                & (truth["friction_power"] > 0))
    out["friction_power"] = friction_power(out["clutch_torque"], out["engine_speed"], out["clutch_speed"], slipping)
    radio_lost = _dropout_mask(n, dt, sensors, rng)
    for name in ("T_flywheel_1", "T_flywheel_2"):
        out[name] = _held_readings(at_sensor["T_flywheel"], node, rng, sensors.node_noise_k, sensors.quantum_k)
        out[name][radio_lost] = np.nan
    out["T_flywheel"] = 0.5 * (out["T_flywheel_1"] + out["T_flywheel_2"])
    wired_channels = [("T_air", at_sensor["T_air"]), ("T_housing", at_sensor["T_housing"]),
                      ("T_ambient", truth["T_ambient"])] + ([("T_engine", truth["T_engine"])] if engine_c else [])
    for name, values in wired_channels:
        out[name] = _held_readings(values, wired, rng, sensors.wired_noise_k, sensors.quantum_k)
    out["load_torque"] = truth["load_torque"]
    frame = pd.DataFrame(out)
    frame.attrs.update(dt=dt, schema=SCHEMA, status="complete", protocol="virtual", events=events,
                       truth={"params": dict(plant.params), "effects": [e.name for e in plant.effects]},
                       true_states=states, source="<simulated bench>")
    return frame
