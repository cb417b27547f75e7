"""Calibration of identify's standard errors: are the reported error bars as large as the true errors?

    .venv/bin/python benchmarks/accuracy_identify.py [--seeds 8] [--hours 2] [--starts 4]

Each seed is a Table 1 run on the simulated bench (sensor noise, held readings, radio drop-outs,
measured torque and speeds) with the paper's nonlinear clutch as the truth. Per seed: the largest error
of R(ω_e), eq. (11), over 700–3000 rpm in both clutch states, and the RMSE on a validation-protocol run
(seed 1000) over its noise floor (the true parameters' RMSE on it). For every parameter,
z = (estimate − truth) / SE; honest standard errors give z a mean near 0 and a spread near 1. The
table shows z for the reported SE and, on the same fits, for two partial error models: the plain
Jacobian (white residuals, exact inputs) and the residual part alone (Newey–West on the scores,
what a HAC sandwich or a residual block bootstrap would give). Exit code 1 if a spread of the
reported z lies outside [0.5, 2].
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlab.model.clutch import convection_resistance
from benchlab.identify.api import identify
from benchlab.identify.evaluate import evaluate
from benchlab.identify.uncertainty import scaled_inverse
from benchlab.model.params import paper_params
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from protocols.table1 import table1_schedule
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

SPREAD_RANGE = (0.5, 2.0)
SPEEDS_RPM = np.linspace(700.0, 3000.0, 47)


def jacobian_errors(jacobian: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """The textbook (JᵀJ)⁻¹s² standard errors: white residuals, inputs exact."""
    n, p = jacobian.shape
    return np.sqrt(np.diag(scaled_inverse(jacobian.T @ jacobian)) * float(residuals @ residuals) / (n - p))


def resistance_error(params: dict, truth: dict) -> float:
    """Largest relative error of R(ω_e), eq. (11), over 700–3000 rpm for both clutch states."""
    channels = {"engine_speed": np.tile(SPEEDS_RPM, 2), "clutch_state": np.repeat([0.0, 1.0], len(SPEEDS_RPM))}
    return float(np.max(np.abs(convection_resistance(params, channels) / convection_resistance(truth, channels) - 1)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--starts", type=int, default=4)
    args = parser.parse_args()
    truth = paper_params("nonlinear")
    z: dict[str, list[np.ndarray]] = {"reported": [], "residuals only": [], "plain Jacobian": []}
    rel_error, rel_se, seconds, r_error, v_ratio = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "validation.h5"
        execute(RunRequest("validation", path, seed=1000, cycles=5, install_signals=False,
                           bench=SimulatedBench(ThermalPlant())))  # the paper's plant: its truth is the model
        validation = load_run(path)
    floor = evaluate(validation, truth)["rmse_K"]
    names: list[str] = []
    for seed in range(1, args.seeds + 1):
        run = run_schedule(table1_schedule(seed, duration_s=3600 * args.hours), ThermalPlant(), seed=seed)
        t0 = time.perf_counter()
        result = identify([run], "nonlinear", starts=args.starts, seed=0)
        seconds.append(time.perf_counter() - t0)
        names = [k for k in result.params if k in result.uncertainty.standard_errors]
        free = result.fit.free_names
        plain = dict(zip(free, jacobian_errors(result.fit.jacobian, result.fit.residuals)))
        error = np.array([result.params[k] - truth[k] for k in names])
        for label, se in (("reported", result.uncertainty.standard_errors),
                          ("residuals only", result.uncertainty.sources["residuals"]), ("plain Jacobian", plain)):
            z[label].append(error / np.array([se[k] for k in names]))
        scale = np.array([abs(truth[k]) for k in names]) / 100
        rel_error.append(error / scale)
        rel_se.append(np.array([result.uncertainty.standard_errors[k] for k in names]) / scale)
        r_error.append(100 * resistance_error(result.params, truth))
        v_ratio.append(evaluate(validation, result.params)["rmse_K"] / floor)
        print(f"seed {seed}: identify {seconds[-1]:.1f} s, max |z| {np.max(np.abs(z['reported'][-1])):.2f}, "
              f"R(w) within {r_error[-1]:.2f} %, validation RMSE {v_ratio[-1]:.3f} x floor", flush=True)
    print(f"\n{args.seeds} seeds x {args.hours:g} h Table 1 runs, nonlinear model, {args.starts} starts; "
          f"identify {np.median(seconds):.1f} s median\n")
    reported = np.array(z["reported"])
    rows = [("mean z", reported.mean(axis=0)), ("spread z", reported.std(axis=0, ddof=1)),
            ("max |z|", np.abs(reported).max(axis=0)),
            ("rms z, residuals only", np.sqrt(np.mean(np.array(z["residuals only"]) ** 2, axis=0))),
            ("rms z, plain Jacobian", np.sqrt(np.mean(np.array(z["plain Jacobian"]) ** 2, axis=0))),
            ("rms error %", np.sqrt(np.mean(np.array(rel_error) ** 2, axis=0))),
            ("mean reported SE %", np.mean(rel_se, axis=0))]
    print(f"{'':24s}" + "".join(f"{k:>8s}" for k in names))
    for label, values in rows:
        print(f"{label:24s}" + "".join(f"{v:8.2f}" if abs(v) >= 0.01 else f"{v:8.3f}" for v in values))
    print(f"\nR(w) over 700-3000 rpm, both states: worst {max(r_error):.2f} %; validation RMSE: worst "
          f"{max(v_ratio):.3f} x the noise floor ({floor:.4f} K)")
    spread = reported.std(axis=0, ddof=1)
    bad = [k for k, s in zip(names, spread) if not SPREAD_RANGE[0] <= s <= SPREAD_RANGE[1]]
    print(f"\nspread of reported z in [{SPREAD_RANGE[0]}, {SPREAD_RANGE[1]}]: "
          f"{'all parameters' if not bad else 'not for ' + ', '.join(bad)}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
