"""Simulated-bench speed: simulated seconds per wall second, full stack.

    .venv/bin/python benchmarks/bench_sim_bench.py [--duration S] [--seed N] [--quick] [--plant reference|paper]

Full stack = `benchlab run table1 --bench sim [--plant P]`: drivetrain + thermal plant (chunked; `--plant`: reference
(default) or paper, docs/plant.md) as providers of the
emulated DMM (SCPI over a sim:// serial URL), ClutchSensorNode gateway (COBS frames over a sim:// URL)
and CAN controllers (in-process CAN bus, DBC frames); the real drivers poll them; the runner executes the
schedule with interlocks; the acquisition writes raw streams, events and the 10 ms /aligned grid into
HDF5 with a flush every simulated second; the file is compacted at the end. Reported: wall and CPU time
(CPU excludes time lost to other processes on a shared machine), the speed factor, where the time goes
(profile of a shorter run), and frames and rows handled. Peer: python-can's own cost per frame (a Message
built and written by its BLFWriter) times the frames per second of bench time (every status frame at its
10 ms DBC cycle): the speed no stack that builds one python-can object per frame can pass. The received
frames travel as arrays (drivers/can_frames.py: simulated bus → driver decode and watch → the BLF writer's
containers, the same driver code a hardware interface feeds frame by frame), so the stack is not bound by it;
so do the frames the PC sends (drivers.can_frames.send_all: one python-can Message per send on hardware). Printed beside it: the whole stack's CPU time
per CAN frame. Target: >= 500x real time (exit 1 if missed).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import cProfile  # noqa: E402
import pstats  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import h5py  # noqa: E402

import benchlab.runner.session as session  # noqa: E402
from benchlab.runner.session import RunRequest, execute  # noqa: E402
from sim_bench.bench import SimulatedBench  # noqa: E402
from sim_bench.reference_plant import DEFAULT_PLANT, PLANTS, plant_named  # noqa: E402

TARGET = 500.0


def one_run(out: Path, duration: float, seed: int, bench: SimulatedBench) -> tuple[float, float, float, dict]:
    opened: list = []  # what the session opens (its drivers' bench, the simulated bench), for the counts below
    real_open = session.open_bench

    def recording(*args, **kwargs):
        opened.append(real_open(*args, **kwargs))
        return opened[-1]

    session.open_bench = recording
    try:
        wall0, cpu0 = time.perf_counter(), time.process_time()
        code, summary = execute(RunRequest("table1", out, seed=seed, duration_s=duration, install_signals=False,
                                           bench=bench))
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    finally:
        session.open_bench = real_open
    assert code == 0, summary.lines()
    with h5py.File(out, "r") as f:
        counts = {k: len(f["raw"][k]["time"]) for k in f["raw"]}
        counts["aligned rows"] = len(f["aligned/time"])
        counts["events"] = len(f["events/time"])
    bench, _, sim, _ = opened[0]
    counts["solver calls"] = sim.physics.solver_calls
    counts["CAN frames sent by emulators"] = sim.can.stats.sent
    counts["CAN frames sent by the driver"] = bench.can.stats.sent
    counts["node frames"] = sim.node.frames_sent
    return summary.sim_s, wall, cpu, counts


def python_can_floor_us(path: Path, n: int = 50_000) -> float:
    """CPU µs per frame that python-can itself costs: one can.Message built and written by its BLFWriter."""
    import can

    cpu0 = time.process_time()
    writer = can.Logger(str(path))
    for i in range(n):
        writer.on_message_received(can.Message(timestamp=i * 0.01, arbitration_id=0x111, data=bytes(8),
                                               is_extended_id=False))
    writer.stop()
    return (time.process_time() - cpu0) / n * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=7200.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="1800 s instead of 2 h")
    ap.add_argument("--plant", choices=sorted(PLANTS), default=DEFAULT_PLANT,
                    help="the simulated clutch (docs/plant.md): the reference plant (default) or the paper's network")
    args = ap.parse_args()
    bench = SimulatedBench(plant_named(args.plant))
    duration = 1800.0 if args.quick else args.duration
    with tempfile.TemporaryDirectory() as tmp:
        execute(RunRequest("table1", Path(tmp) / "warm.h5", cycles=1, install_signals=False, bench=bench))  # imports, numba
        sim_s, wall, cpu, counts = one_run(Path(tmp) / "run.h5", duration, args.seed, bench)
        print(f"table1 {duration:.0f} s planned, {sim_s:.0f} s simulated, {args.plant} plant")
        print(f"  wall {wall:6.2f} s  -> {sim_s / wall:6.0f}x real time")
        print(f"  cpu  {cpu:6.2f} s  -> {sim_s / cpu:6.0f}x real time per core (other load excluded)")
        for k, v in counts.items():
            print(f"  {k:30s} {v:>10,d}")
        prof = cProfile.Profile()
        prof.enable()
        execute(RunRequest("table1", Path(tmp) / "prof.h5", seed=args.seed, duration_s=600.0, install_signals=False,
                           bench=bench))
        prof.disable()
        stats = pstats.Stats(prof)
        total = sum(v[2] for v in stats.stats.values())
        groups = {"emulators (sim_bench/emulators)": "sim_bench/emulators", "drivers": "/drivers/",
                  "physics (sim_bench/bench, plants, solver)": ("sim_bench/bench", "sim_bench/plant", "sim_bench/reference_plant", "benchlab/network/",
                                                              "drivetrain.py"),
                  "acquisition (benchlab/acquire)": "benchlab/acquire", "runner + devices": "benchlab/runner"}
        print("  self time by layer (600 s profile):")
        for label, keys in groups.items():
            keys = (keys,) if isinstance(keys, str) else keys
            t = sum(v[2] for k, v in stats.stats.items() if any(s in k[0] for s in keys))
            print(f"    {label:42s} {100 * t / total:5.1f} %")
        frames = counts["CAN frames sent by emulators"] + counts["CAN frames sent by the driver"]
        frames_per_s = frames / sim_s
        floor_us = python_can_floor_us(Path(tmp) / "floor.blf")
        print(f"  peer: python-can alone (can.Message + BLFWriter per frame) {floor_us:.2f} us/frame x "
              f"{frames_per_s:.0f} frames/s of bench time -> at most {1e6 / (floor_us * frames_per_s):.0f}x real time;"
              f" the full stack reaches {sim_s / cpu / (1e6 / (floor_us * frames_per_s)):.2f} of that, "
              f"{cpu / frames * 1e6:.2f} us CPU per CAN frame with everything else included")
    ok = sim_s / cpu >= TARGET
    print(f"target >= {TARGET:.0f}x real time (per core): {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
