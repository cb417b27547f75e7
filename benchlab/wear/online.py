"""The online temperature-plus-wear update a transmission control unit would run every sample, in scalars.

Discrete matrices [Ad Bd] are precomputed once for a grid of operating points (engine speed × clutch
state, the arguments of eq. 11); each sample looks up the nearest point, updates the four temperatures
and adds the wear and μ-loss increments of eq. (3) at the current lining temperatures.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence

import numpy as np

from benchlab.model.params import ModelParams
from benchlab.network.solver import discretise
from benchlab.wear.clutchfile import ClutchSpec
from benchlab.wear.thermal import split_network

DEFAULT_SPEED_STEP_RPM = 25.0
DEFAULT_MAX_SPEED_RPM = 8000.0


def interp(xs: Sequence[float], ys: Sequence[float], v: float) -> float:
    """Scalar table lookup, linear between points and clamped at the edges (as Map1D)."""
    if v <= xs[0]:
        return ys[0]
    if v >= xs[-1]:
        return ys[-1]
    i = bisect_right(xs, v)
    return ys[i - 1] + (ys[i] - ys[i - 1]) * (v - xs[i - 1]) / (xs[i] - xs[i - 1])


class LiningWear:
    """Eq. (3) sample by sample, in scalars: wear = [s_P, s_F, δ_P, δ_F] (mm per face, fraction) from the friction
    power and the two lining temperatures; the one online wear update (OnlineWear, the observer)."""

    def __init__(self, spec: ClutchSpec, dt: float, split: float = 0.5) -> None:
        self.split = split
        start = spec.initial  # the wear the clutch already has
        self.wear = [start.wear_plate_mm, start.wear_flywheel_mm, start.loss_plate, start.loss_flywheel]
        self.wear_rate = spec.maps["wear_rate"].as_lists()
        self.loss_rate = spec.maps["friction_loss"].as_lists()
        self.per_face = dt / spec.faces_per_side
        self.inv_area = 1.0 / spec.area_mm2

    def add(self, power_w: float, plate_c: float, flywheel_c: float) -> None:
        """Add one sample's wear: `split`·P on the plate side at ϑ_P, the rest on the flywheel side at ϑ_F."""
        if power_w > 0.0:
            wear = self.wear
            for side, share, temperature in ((0, self.split, plate_c), (1, 1.0 - self.split, flywheel_c)):
                energy = share * power_w * self.per_face
                wear[side] += interp(*self.wear_rate, temperature) * energy * self.inv_area
                wear[side + 2] += interp(*self.loss_rate, temperature) * energy * 1e-6


class OnlineWear:
    """State: temperatures x = [ϑ_P, ϑ_F, ϑ_A, ϑ_T] (degC) and wear = [s_P, s_F, δ_P, δ_F] (mm per face, fraction)."""

    def __init__(self, params: ModelParams, spec: ClutchSpec, dt: float, x0: Sequence[float], split: float = 0.5,
                 speed_step_rpm: float = DEFAULT_SPEED_STEP_RPM, max_speed_rpm: float = DEFAULT_MAX_SPEED_RPM) -> None:
        grid = np.arange(0.0, max_speed_rpm + 0.5 * speed_step_rpm, speed_step_rpm)
        zeros = np.zeros(2 * len(grid))
        channels = {"engine_speed": np.concatenate([grid, grid]), "clutch_state": np.repeat([0.0, 1.0], len(grid)),
                    "clutch_speed": zeros, "friction_power": zeros, "T_ambient": zeros}
        disc = discretise(split_network(split), params, channels, dt)
        points = [disc.op_index[:len(grid)], disc.op_index[len(grid):]]  # clutch open, clamped
        self.tables = [[(disc.Ad[op].tolist(), disc.Bd[op].tolist()) for op in ops] for ops in points]
        self.inv_step, self.last = 1.0 / speed_step_rpm, len(grid) - 1
        self.dt, self.split = dt, split
        self.x = [float(v) for v in x0]
        self.lining = LiningWear(spec, dt, split)
        self.wear = self.lining.wear

    def step(self, engine_rpm: float, clamped: bool, power_w: float, t_engine: float, t_ambient: float) -> None:
        """Advance one sample: wear at the current lining temperatures, then the ZOH temperature update."""
        x = self.x
        self.lining.add(power_w, x[0], x[1])
        i = min(max(int(engine_rpm * self.inv_step + 0.5), 0), self.last)
        ad, bd = self.tables[1 if clamped else 0][i]
        u = (self.split * power_w, (1.0 - self.split) * power_w, t_engine, t_ambient)
        self.x = [a[0] * x[0] + a[1] * x[1] + a[2] * x[2] + a[3] * x[3]
                  + b[0] * u[0] + b[1] * u[1] + b[2] * u[2] + b[3] * u[3] for a, b in zip(ad, bd)]
