"""Cost of the online temperature-plus-wear update per 10 ms sample, beside the budget and a naive peer.

    .venv/bin/python benchmarks/bench_wear.py [--minutes M] [--peer-samples N]

The update a transmission control unit runs every sample (benchlab.wear.online.OnlineWear): look up
precomputed [Ad Bd] for the current operating point (engine speed grid x clutch state, eq. 11), update
the four temperatures, add the wear and mu-loss increments of eq. (3). Timed on a simulated Table 1 run:
  - OnlineWear in pure-Python scalars (what this repository ships),
  - the same update compiled with numba (a stand-in for the control unit's C code),
  - the naive peer: per sample, build the continuous A, B of eq. 6-11 and take scipy.linalg.expm of the
    augmented 8x8 matrix, then the same update (timed on a slice, per sample).
Each is checked against benchlab.simulate + the offline wear integral on the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.linalg
from numba import njit

from benchlab.model.params import paper_params
from benchlab.network.simulation import simulate
from benchlab.wear.clutchfile import default_clutch
from benchlab.wear.energy import engagement_spans, run_friction_power
from benchlab.wear.model import wear_history
from benchlab.wear.online import OnlineWear
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

BUDGET_US = 10_000.0  # one 10 ms control-unit sample


def continuous(p: dict, engine_rpm: float, clamped: bool) -> tuple[np.ndarray, np.ndarray]:
    """A (4x4) and B (4x4, inputs P_plate, P_flywheel, T_eng, T_amb) of eq. 6-9 with R_PA = R_FA from eq. 11."""
    a, b = (p["a1"], p["b1"]) if clamped else (p["a2"], p["b2"])
    g = 1.0 / (a * np.exp(b * engine_rpm) + p["R0"])
    g_at, g_feng, g_tamb = 1.0 / p["R_AT"], 1.0 / p["R_Feng"], 1.0 / p["R_Tamb"]
    A = np.array([[-g, 0.0, g, 0.0], [0.0, -g - g_feng, g, 0.0], [g, g, -2 * g - g_at, g_at],
                  [0.0, 0.0, g_at, -g_at - g_tamb]])
    B = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, g_feng, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, g_tamb]])
    c = np.array([p["C_P"], p["C_F"], p["C_A"], p["C_T"]])[:, None]
    return A / c, B / c


def naive_peer(p: dict, spec, dt: float, x0: np.ndarray, speed, clamped, power, amb, n: int):
    """Per-sample expm of the augmented system, then the same update and wear increment."""
    x = x0.copy()
    wear = np.zeros(4)
    k_x, k_y = spec.maps["wear_rate"].x, spec.maps["wear_rate"].y
    l_x, l_y = spec.maps["friction_loss"].x, spec.maps["friction_loss"].y
    aug = np.zeros((8, 8))
    for k in range(n):
        if power[k] > 0:
            e = 0.5 * power[k] * dt
            for side in (0, 1):
                wear[side] += np.interp(x[side], k_x, k_y) * e / spec.area_mm2
                wear[side + 2] += np.interp(x[side], l_x, l_y) * e * 1e-6
        A, B = continuous(p, speed[k], clamped[k])
        aug[:4, :4], aug[:4, 4:] = A * dt, B * dt
        E = scipy.linalg.expm(aug)
        x = E[:4, :4] @ x + E[:4, 4:] @ np.array([0.5 * power[k], 0.5 * power[k], amb[k], amb[k]])
    return x, wear


@njit(cache=True)
def compiled_loop(ad, bd, inv_step, speed, clamped, power, amb, x0, kx, ky, lx, ly, per_face, inv_area):
    x = x0.copy()
    nxt = np.empty(4)
    wear = np.zeros(4)
    last = ad.shape[1] - 1
    for k in range(speed.shape[0]):
        if power[k] > 0.0:
            e = 0.5 * power[k] * per_face
            for side in range(2):
                wear[side] += np.interp(x[side], kx, ky) * e * inv_area
                wear[side + 2] += np.interp(x[side], lx, ly) * e * 1e-6
        i = min(max(int(speed[k] * inv_step + 0.5), 0), last)
        s = 1 if clamped[k] else 0
        u0, u2 = 0.5 * power[k], amb[k]
        for r in range(4):
            nxt[r] = (ad[s, i, r, 0] * x[0] + ad[s, i, r, 1] * x[1] + ad[s, i, r, 2] * x[2] + ad[s, i, r, 3] * x[3]
                      + bd[s, i, r, 0] * u0 + bd[s, i, r, 1] * u0 + bd[s, i, r, 2] * u2 + bd[s, i, r, 3] * u2)
        for r in range(4):
            x[r] = nxt[r]
    return x, wear


def line(label: str, us: float, peer_us: float | None = None) -> None:
    extra = f"   {peer_us / us:8.0f}x faster than the peer" if peer_us else ""
    print(f"  {label:46s} {us:10.3f} us/sample   {us / BUDGET_US * 100:8.4f} % of the 10 ms budget"
          f"   ({BUDGET_US / us:10,.0f}x headroom){extra}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0, help="simulated Table 1 run length")
    parser.add_argument("--peer-samples", type=int, default=5000, help="samples for the (slow) expm peer")
    args = parser.parse_args()
    params, spec = paper_params(), default_clutch()
    run = run_schedule(table1_schedule(1, duration_s=args.minutes * 60), ThermalPlant(), seed=1)
    dt = run.attrs["dt"]
    n = len(run) - 1  # steps from row 0 to the last row of the offline simulation
    speed = run["engine_speed"].to_numpy()
    clamped = run["clutch_state"].to_numpy() >= 0.5
    power = run_friction_power(run)
    amb = run["T_ambient"].to_numpy()
    offline = simulate(run, params)
    x0 = offline.iloc[0].to_numpy()
    reference = wear_history(spec, power, 0.5, offline["T_pressure_plate"].to_numpy(),
                             offline["T_flywheel"].to_numpy(), dt)
    print(f"bench_wear: {n:,} samples of a simulated Table 1 run (dt = {dt * 1e3:.0f} ms, nonlinear model), "
          f"{len(engagement_spans(power > 0, dt))} engagements")

    online = OnlineWear(params, spec, dt, x0)
    t0 = time.perf_counter()
    for k in range(n):
        online.step(speed[k], clamped[k], power[k], amb[k], amb[k])
    python_us = (time.perf_counter() - t0) / n * 1e6

    ad = np.array([[np.array(t[0]) for t in row] for row in online.tables])
    bd = np.array([[np.array(t[1]) for t in row] for row in online.tables])
    maps = [np.asarray(v) for v in (*spec.maps["wear_rate"].as_lists(), *spec.maps["friction_loss"].as_lists())]
    compiled_args = (ad, bd, online.inv_step, speed[:n], clamped[:n], power[:n], amb[:n], x0, *maps,
                     dt / spec.faces_per_side, 1.0 / spec.area_mm2)
    compiled_loop(*compiled_args)  # compile
    t0 = time.perf_counter()
    x_c, wear_c = compiled_loop(*compiled_args)
    compiled_us = (time.perf_counter() - t0) / n * 1e6

    m = min(args.peer_samples, n)
    t0 = time.perf_counter()
    x_p, wear_p = naive_peer(params, spec, dt, x0, speed, clamped, power, amb, m)
    peer_us = (time.perf_counter() - t0) / m * 1e6

    end = offline.to_numpy()[n]
    wear_ref = np.array([reference.cumulative[k][n - 1] for k in ("wear_plate_mm", "wear_flywheel_mm")])
    print("accuracy against benchlab.simulate + offline wear (whole run; peer on its slice):")
    print(f"  OnlineWear (python)   max |dT| at the end {np.max(np.abs(np.array(online.x) - end)):.2e} K, "
          f"wear rel. diff {np.max(np.abs(np.array(online.wear[:2]) / wear_ref - 1)):.2e}")
    print(f"  compiled loop         max |dT| at the end {np.max(np.abs(x_c - end)):.2e} K, "
          f"wear rel. diff {np.max(np.abs(wear_c[:2] / wear_ref - 1)):.2e}")
    slice_ref = np.array([reference.cumulative[k][m - 1] for k in ("wear_plate_mm", "wear_flywheel_mm")])
    print(f"  expm peer ({m} smp)  max |dT| {np.max(np.abs(x_p - offline.to_numpy()[m])):.2e} K, "
          f"wear rel. diff {np.max(np.abs(wear_p[:2] - slice_ref)) / max(slice_ref.max(), 1e-300):.2e}")
    print("cost per sample (one core):")
    line("naive peer: per-sample scipy.linalg.expm", peer_us)
    line("OnlineWear.step, pure-Python scalars", python_us, peer_us)
    line("same update compiled (numba, ~control-unit C)", compiled_us, peer_us)


if __name__ == "__main__":
    main()
