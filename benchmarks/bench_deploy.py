"""Budgets of the C module `benchlab deploy` generates, beside the Python online observer and the 10 ms task.

    .venv/bin/python benchmarks/bench_deploy.py [--minutes M] [--seed N]

Data: a simulated Table 1 run (sim_bench.virtual_run, the paper's nonlinear plant), M minutes at 10 ms. Model: the
paper's nonlinear clutch with its parameters, T_air as the only sensor, online wear (the issue's budget case).
Measured: bytes of state (`sizeof`), bytes of code and constants (`size` of the -O2 object), floating-point
operations per step (counted from the source's loops), host time per step of the compiled module (float and
double; wall time of the driver's loop over the run divided by the samples, best of 3), the Python
`OnlineObserver.step` on the same samples, and how often the operating point moved (a new discretisation).
Targets (issue 43): state <= 1 KiB, a step <= 2 us; deviations from the Python observer as in the tests.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlab.deploy import verify
from benchlab.deploy.module import TASK_BUDGET_US, flops_per_step, write_module
from benchlab.deploy.plan import make_plan
from benchlab.model.params import paper_params
from benchlab.wear.clutchfile import default_clutch
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule
from targets import load, print_target, summarise_targets  # benchmarks/targets.py, beside this script

STATE_TARGET_BYTES = 1024
STEP_TARGET_US = 2.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    started = time.perf_counter()
    run = run_schedule(table1_schedule(args.seed, duration_s=60 * args.minutes), ThermalPlant(), seed=args.seed)
    plan = make_plan(paper_params("nonlinear"), ["T_air"], float(run.attrs["dt"]), default_clutch())
    began = time.process_time()
    theirs = verify.reference(plan, run)
    python_us = 1e6 * (time.process_time() - began) / len(run)
    inputs, _, _ = verify.run_inputs(plan, run)
    moved = np.mean(np.any(np.diff(np.rint(inputs[:, [plan.inputs.index(c) for c in plan.key]]), axis=0) != 0,
                           axis=1))
    print(f"{len(run)} samples ({args.minutes:g} min), {plan.model} clutch, sensor T_air, online wear; "
          f"operating point moved on {100 * moved:.0f} % of the samples; {load()}")
    flops = flops_per_step(plan)
    print(f"floating-point operations per step: {flops['filter']} (filter) + {flops['discretise']} "
          f"(discretisation, when the point moves)")
    targets = []
    for real in ("float", "double"):
        with tempfile.TemporaryDirectory() as scratch:
            directory = Path(scratch)
            write_module(directory, plan, real)
            built = verify.build(directory, plan)
            runs = [verify.run_module(built, plan, run, theirs["x0"], real) for _ in range(3)]
        best = min(r["step_us"] for r in runs)
        compared = verify.compare(plan, runs[0], theirs)
        worst = max(compared["max_abs_dev_K"].values())
        print(f"{real:6s}: state {runs[0]['state_bytes']} B, code {built.code_bytes} B, {best:.3f} us per step "
              f"({100 * best / TASK_BUDGET_US:.4f} % of the {TASK_BUDGET_US:.0f} us task; Python observer "
              f"{python_us:.1f} us, {python_us / best:.0f}x); largest deviation {worst:.2g} K, plate sigma "
              f"{compared['plate_sigma_rel_dev']:.2g}, wear {compared['wear_rel_dev']:.2g}")
        if real == "float":
            targets += [("state (float)", f"{runs[0]['state_bytes']} B vs <= {STATE_TARGET_BYTES} B",
                         runs[0]["state_bytes"] <= STATE_TARGET_BYTES),
                        ("step (float)", f"{best:.2f} us vs <= {STEP_TARGET_US:g} us", best <= STEP_TARGET_US),
                        ("temperatures (float)", f"{worst:.2g} K vs <= 0.05 K", worst <= 0.05)]
        else:
            targets.append(("temperatures (double)", f"{worst:.2g} K vs <= 1e-6 K", worst <= 1e-6))
    print()
    for target in targets:
        print_target(*target)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    raise SystemExit(main())
