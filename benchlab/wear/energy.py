"""Friction power and energy (eq. 2, 4) from measured clutch torque and slip, and the engagements they form."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from benchlab.drivetrain import RPM, friction_power, slipping_by_speed

#: Slip pauses up to this long (speed noise at synchronisation) do not split an engagement.
DEFAULT_GAP_S = 0.2


def held(run: pd.DataFrame, name: str) -> np.ndarray:
    """A channel with drop-outs held at the last valid value (zero-order hold, as the simulator's inputs)."""
    return pd.Series(run[name].to_numpy(np.float64)).ffill().bfill().fillna(0.0).to_numpy()


def slip_rad_s(run: pd.DataFrame) -> np.ndarray:
    """Δω = ω_e − ω_c in rad/s."""
    return (held(run, "engine_speed") - held(run, "clutch_speed")) * RPM


def slipping(run: pd.DataFrame) -> np.ndarray:
    """Clamped and slipping: the run's friction_power > 0 where present, else |Δω| above the slip threshold."""
    clamped = held(run, "clutch_state") >= 0.5
    recorded = run["friction_power"].to_numpy(np.float64)
    by_slip = slipping_by_speed(held(run, "engine_speed"), held(run, "clutch_speed"))
    return clamped & np.where(np.isnan(recorded), by_slip, recorded > 0)


def run_friction_power(run: pd.DataFrame) -> np.ndarray:
    """P = |T_c · Δω| in W while slipping, 0 otherwise (contract: friction_power), from the run's held channels."""
    return friction_power(held(run, "clutch_torque"), held(run, "engine_speed"), held(run, "clutch_speed"),
                          slipping(run))


def friction_energy(power: np.ndarray, dt: float) -> float:
    """E = Σ P[k]·dt: eq. (2) under the simulator's zero-order hold, in J."""
    return float(np.sum(power) * dt)


def engagement_spans(active: np.ndarray, dt: float, gap_s: float = DEFAULT_GAP_S) -> list[tuple[int, int]]:
    """Half-open sample ranges of contiguous slipping, gaps of at most `gap_s` bridged."""
    edges = np.diff(np.concatenate(([0], active.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    spans: list[tuple[int, int]] = []
    for start, stop in zip(starts, stops):
        if spans and (start - spans[-1][1]) * dt <= gap_s:
            spans[-1] = (spans[-1][0], int(stop))
        else:
            spans.append((int(start), int(stop)))
    return spans


def engagement_table(spans: list[tuple[int, int]], dt: float, power: np.ndarray, split: float,
                     temperatures: Mapping[str, np.ndarray], increments: Mapping[str, np.ndarray]) -> pd.DataFrame:
    """One row per engagement: timing, energy (total and per side), peak power, mean and peak lining
    temperature while slipping, and the sum of each per-sample increment (wear, μ loss) over it."""
    n = len(power)
    rows = []
    for i, (a, b) in enumerate(spans):
        slip = power[a:b] > 0  # spans come from power > 0, so at least one sample
        energy = float(np.sum(power[a:b]) * dt)
        row = {"start_s": a * dt, "end_s": b * dt, "slip_time_s": float(np.count_nonzero(slip) * dt),
               "energy_J": energy, "peak_power_W": float(np.max(power[a:b])),
               "energy_plate_J": split * energy, "energy_flywheel_J": (1.0 - split) * energy,
               "cycle_s": ((spans[i + 1][0] if i + 1 < len(spans) else n) - a) * dt}
        for name, values in temperatures.items():
            row[f"{name}_mean_C"] = float(np.mean(values[a:b][slip]))
            row[f"{name}_max_C"] = float(np.max(values[a:b]))
        for name, values in increments.items():
            row[name] = float(np.sum(values[a:b]))
        rows.append(row)
    columns = ["start_s", "end_s", "slip_time_s", "energy_J", "peak_power_W", "energy_plate_J",
               "energy_flywheel_J", "cycle_s"]
    columns += [f"{name}_{kind}_C" for name in temperatures for kind in ("mean", "max")] + list(increments)
    return pd.DataFrame(rows, columns=columns)
