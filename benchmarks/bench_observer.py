"""Cost of one online observer step (Kalman filter + online wear) per 10 ms sample, beside the budget and a numpy peer.

    .venv/bin/python benchmarks/bench_observer.py [--minutes M] [--seed N]

Data: a Table 1 run on the simulated bench through the drivers (benchlab.runner.session.execute), M minutes.
Timed in CPU time (time.process_time, one core), per sample, on the clutch model (4 states) with T_air as the
observer's only sensor and the estimated plate and flywheel temperatures feeding the online wear:
  - OnlineObserver.step (what this repository ships): operating-point lookup, input laws, the compiled
    filter step (benchlab.observer.kalman), LiningWear;
  - the same with the convection law corrected online (--adapt R_PA: 5 states, extended filter);
  - the peer: the same filter step written in plain numpy (x = Ad x + Bd u, P = Ad P Adᵀ + Γ Q Γᵀ, scalar
    update), with the same operating-point lookup and wear, as one would first write it;
  - the batch filter of `benchlab observe` over the whole run, per sample.
Every variant is checked against the batch filter on the same run. Target: <= 10 us per step (clutch model).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlab.observer.batch import fresh, observe
from benchlab.observer.online import OnlineObserver
from benchlab.model.params import paper_params
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from benchlab.network.simulation import input_channels
from benchlab.wear.clutchfile import default_clutch
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant
from targets import load, print_target, summarise_targets  # benchmarks/targets.py, beside this script

BUDGET_US = 10_000.0  # one 10 ms control-unit sample
TARGET_US = 10.0
INPUTS = ("engine_speed", "clutch_state", "friction_power", "T_ambient")
STATES = ["T_pressure_plate", "T_flywheel", "T_air", "T_housing"]


class NumpyPeer(OnlineObserver):
    """The online observer with its filter step in plain numpy instead of the compiled kernel."""

    def step(self, inputs, measurement):  # noqa: ANN001, ANN201 - the parent's signature
        inputs = inputs.tolist() if isinstance(inputs, np.ndarray) else inputs
        channels = dict(zip(self.inputs, inputs))
        point = self._points.get(self._key(inputs)) or self._point(channels)
        self._held = inputs
        u = np.array([law(channels) for law in self._laws], dtype=float)
        n, m = len(self.states), self.model.m
        ab = point[0]
        a, b, gamma = ab[:, :n], ab[:, n:n + m], ab[:, n + m:]
        x, P = self.z, self.P
        for value, state, variance in zip(measurement, self.model.sensor_state, self.model.sensor_var):
            if not np.isnan(value):
                gain = P[:, state] / (P[state, state] + variance)
                x += gain * (value - x[state])
                P -= np.outer(gain, P[state, :])
        self._out[0] = x
        self._out[1] = np.sqrt(np.diag(P))
        self.z = a @ x + b @ u
        self.P = a @ P @ a.T + gamma @ np.diag(self._q) @ gamma.T
        if self.lining is not None:
            self.lining.add(inputs[self._power], float(x[self._plate]), float(x[self._flywheel]))
        return self._estimate


def per_step(observer: OnlineObserver, inputs: list, readings: np.ndarray) -> tuple[float, np.ndarray]:
    """CPU us per step over the run, and the estimated temperatures (N, 4)."""
    out = np.empty((len(inputs), 4))
    started = time.process_time()
    for k in range(len(inputs)):
        out[k] = observer.step(inputs[k], readings[k]).temperature
    return (time.process_time() - started) / len(inputs) * 1e6, out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="length of the simulated Table 1 run")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "table1.h5"
        code, _ = execute(RunRequest("table1", path, seed=args.seed, duration_s=args.minutes * 60,
                                     install_signals=False, bench=SimulatedBench(ThermalPlant())))  # paper plant
        assert code == 0, code
        run = load_run(path)
    params, clutch, dt = paper_params(), default_clutch(), float(run.attrs["dt"])
    channels = input_channels(run)
    inputs = np.column_stack([channels[c] for c in INPUTS]).tolist()
    readings = fresh(run[["T_air"]].to_numpy())
    print(f"bench_observer: {len(run):,} samples of a Table 1 run through the drivers (dt = {dt * 1e3:.0f} ms), "
          f"clutch model, sensor T_air, online wear; {load()}")
    batch = observe(run, params, ["T_air"], initial_offset_k=30.0)
    reference = batch.estimate[STATES].to_numpy()
    observe(run, params, ["T_air"], initial_offset_k=30.0, adapt=("R_PA",))  # compile both kernels' paths
    started_batch = time.process_time()
    batch_adapt = observe(run, params, ["T_air"], initial_offset_k=30.0, adapt=("R_PA",))
    batch_us = (time.process_time() - started_batch) / len(run) * 1e6
    results = {}
    for label, cls, adapt, ref in (("OnlineObserver.step", OnlineObserver, (), reference),
                                   ("OnlineObserver.step, --adapt R_PA", OnlineObserver, ("R_PA",),
                                    batch_adapt.estimate[STATES].to_numpy()),
                                   ("numpy peer (same step in numpy)", NumpyPeer, (), reference)):
        make = lambda: cls(params, ["T_air"], INPUTS, batch.initial, dt, noise=batch.noise, clutch=clutch,  # noqa: E731
                           adapt=adapt)
        per_step(make(), inputs[:2000], readings[:2000])  # compile, warm the caches of the interpreter
        us, estimate = per_step(make(), inputs, readings)
        results[label] = us
        print(f"  {label:<36} max |online - batch| {np.max(np.abs(estimate - ref)):.1e} K")
    print("CPU time per 10 ms sample (one core):")
    peer = results["numpy peer (same step in numpy)"]
    for label, us in results.items():
        print(f"   {label:<36}{us:8.2f} us   {us / BUDGET_US * 100:6.3f} % of the 10 ms budget   "
              f"{peer / us:5.1f}x the numpy peer")
    print(f"   {'batch filter (benchlab observe), adapt':<36}{batch_us:8.3f} us per sample")
    ours = results["OnlineObserver.step"]
    targets = [("online step, clutch model", f"{ours:.2f} us vs <= {TARGET_US:g} us", ours <= TARGET_US),
               ("faster than the numpy peer", f"{peer / ours:.1f}x vs > 1x", peer > ours)]
    print("\nTargets:")
    for target in targets:
        print_target(*target)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    raise SystemExit(main())
