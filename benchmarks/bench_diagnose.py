"""Diagnose speed: two 2 h runs at 10 ms (1.44 M samples) with a hidden effect, against the 60 s budget.

Prints the wall time, the samples per second, the ratio to the bench time the data took to record
(the physical limit a test engineer waits for anyway) and to the 60 s target, and per finding the
held-out RMSE before and after with the gain and the truth's gain (1 - floor / baseline).
Beside it, on the same run files: the engine of another commit (`--peer-ref`, default the last commit with
the hand-written library, before the generated candidates), exported with `git archive` and run in a
subprocess; and the naive peer on the first 30 minutes of each run: the same diagnosis with one scipy
expm per operating point instead of the compiled batched ZOH.

    python benchmarks/bench_diagnose.py [--quick] [--peer-ref REF] [--plant paper|reference]

`--plant reference`: the main job's plant as it is (no hidden effect; its misfit is the plant's richness), issue
45's figure for two 2 h runs.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.linalg

import benchlab.network.solver as solver
from benchlab.diagnose import diagnose
from benchlab.diagnose.engine import STEP_S
from benchlab.identify.data import prepare
from benchlab.runfile import write_run
from benchlab.model.params import paper_params
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.reference_plant import plant_named
from sim_bench.virtual_run import run_schedule

TARGET_S = 60.0
PEER_SLICE_S = 1800.0
PEER_REF = "daffdc5"  # the engine with the hand-written clutch library (issue 18's starting point)
ROOT = Path(__file__).resolve().parents[1]
PEER_SCRIPT = """
import sys, time
from benchlab.diagnose import diagnose
from benchlab.runfile import load_run
runs = [load_run(p) for p in sys.argv[1:]]
start = time.perf_counter()
result = diagnose(runs, baseline="nonlinear")
print(time.perf_counter() - start, [f["candidate"] for f in result["findings"]])
"""


def _runs(duration_s: float, seeds: tuple[int, ...], plant_name: str):
    """Table 1 runs of `seeds`: the paper's clutch with a hidden gearbox-churning source, or the reference plant as
    it is (richer than the model: the main job's plant)."""
    out = []
    for seed in seeds:
        plant = (plant_named("reference") if plant_name == "reference"
                 else P.ThermalPlant(paper_params("nonlinear"), [P.gearbox_churning(40.0)]))
        out.append((plant, run_schedule(table1_schedule(seed, duration_s=duration_s), plant, seed=seed)))
    return out


def _floor(pairs) -> float:
    squared = []
    for plant, run in pairs:
        data = prepare(run, STEP_S)
        truth = plant.sensor_temperatures(run.attrs["true_states"])
        for channel, target in data.targets.items():
            valid = np.isfinite(target)
            squared.append((truth[channel][:: data.block][: len(target)][valid] - target[valid]) ** 2)
    return float(np.sqrt(np.mean(np.concatenate(squared))))


def cpu_seconds() -> float:
    """User + system CPU time of this process and of every child it has waited for (forked fit workers, the peer's
    process and its own workers): the cost on a shared machine, where wall time is the other agents' load."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _timed(runs) -> tuple[float, float, dict]:
    """Wall seconds, CPU seconds and the JSON of one diagnosis."""
    start, cpu = time.perf_counter(), cpu_seconds()
    result = diagnose(runs, baseline="nonlinear")
    return time.perf_counter() - start, cpu_seconds() - cpu, result


def _peer(ref: str, runs) -> tuple[float, float, str]:
    """Wall time, CPU time and findings of the engine at git `ref` on the same runs (its benchlab exported, run
    apart; the CPU time is its process's with its workers, reading the files included)."""
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "archive", ref, "benchlab", "models"], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        paths = []
        for i, run in enumerate(runs):
            paths.append(str(Path(tmp) / f"run{i}.h5"))
            write_run(paths[-1], run, run.attrs["dt"], protocol="table1")
        cpu = cpu_seconds()
        out = subprocess.run([sys.executable, "-c", PEER_SCRIPT, *paths], cwd=tmp, check=True, capture_output=True,
                             text=True, env={**os.environ, "PYTHONPATH": tmp}).stdout.strip()
        cpu = cpu_seconds() - cpu
    seconds, findings = out.split(" ", 1)
    return float(seconds), cpu, findings


def _naive_zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One scipy expm of the augmented matrix per operating point: the textbook ZOH."""
    m, n, k = a.shape[0], a.shape[1], b.shape[2]
    ad, bd = np.empty_like(a), np.empty_like(b)
    for i in range(m):
        block = np.zeros((n + k, n + k))
        block[:n, :n], block[:n, n:] = a[i], b[i]
        e = scipy.linalg.expm(block * dt)
        ad[i], bd[i] = e[:n, :n], e[:n, n:]
    return ad, bd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two 45 min runs instead of two 2 h runs")
    parser.add_argument("--peer-ref", default=PEER_REF, help="git commit whose engine runs beside this one")
    parser.add_argument("--no-slice", action="store_true", help="skip the 30 min slice with scipy's expm per point")
    parser.add_argument("--plant", choices=("paper", "reference"), default="paper",
                        help="the paper's clutch with a hidden churning source (default), or the main job's plant")
    args = parser.parse_args()
    duration = 2700.0 if args.quick else 7200.0
    pairs = _runs(duration, (1, 2), args.plant)
    runs = [run for _, run in pairs]
    samples = sum(len(r) for r in runs)
    elapsed, cpu, result = _timed(runs)
    floor = _floor(pairs)
    print(f"load average {os.getloadavg()[0]:.2f}; two runs of {duration / 3600:.1f} h on the {args.plant} plant, "
          f"{samples} samples at 10 ms")
    print(f"diagnose: {elapsed:.1f} s wall, {cpu:.1f} s CPU (all processes; {cpu / 2:.1f} s on 2 free cores), "
          f"{samples / elapsed / 1e3:.0f} k samples/s, "
          f"{2 * duration / elapsed:.0f}x the bench time, {TARGET_S / elapsed:.2f}x the {TARGET_S:.0f} s target")
    base = result["baseline"]["rmse_K"]
    print(f"baseline held-out RMSE {base:.4f} K; floor (true temperatures vs targets) {floor:.4f} K; "
          f"truth's gain {100 * (1 - floor / base):.1f} %")
    for f in result["findings"]:
        print(f"  {f['signal']}/{f['mechanism']} ({f['candidate']}): {f['rmse_before_K']:.4f} -> "
              f"{f['rmse_after_K']:.4f} K, gain {f['gain_pct']:.1f} %, p = {f['p_value']:.1e}, BIC change {f['bic_delta']:.0f}")
    peer_s, peer_cpu, peer_findings = _peer(args.peer_ref, runs)
    print(f"peer engine at {args.peer_ref} on the same runs: {peer_s:.1f} s wall, {peer_cpu:.1f} s CPU (this engine "
          f"{elapsed:.1f} s, {cpu:.1f} s CPU: {cpu / peer_cpu:.2f}x the peer's CPU), findings {peer_findings}")
    if args.no_slice:
        return
    slice_runs = [run.iloc[: int(PEER_SLICE_S / run.attrs["dt"])].copy() for run in runs]
    for piece, run in zip(slice_runs, runs):
        piece.attrs.update(run.attrs)
    fast_slice, _, _ = _timed(slice_runs)
    compiled = solver._zoh
    solver._zoh = _naive_zoh  # the solver looks its ZOH up by name at each call
    try:
        naive_slice, _, _ = _timed(slice_runs)
    finally:
        solver._zoh = compiled
    print(f"peer on the first {PEER_SLICE_S / 60:.0f} min of each run: compiled ZOH {fast_slice:.1f} s, "
          f"scipy expm per operating point {naive_slice:.1f} s: {naive_slice / fast_slice:.1f}x")


if __name__ == "__main__":
    main()
