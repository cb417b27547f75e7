"""MDF4 export of a 2 h run beside asammdf's own DataFrame import of the same /aligned data, CPU time.

    .venv/bin/python benchmarks/bench_export.py [--hours H] [--quick]

The run file: a Table 1 schedule played by the batch simulator (`sim_bench.virtual_run.run_schedule`), its
channels fed as the simulated bench's raw streams (`benchlab.runner.devices.bench_layout`: three CAN status
streams at 100 Hz, the flywheel node at 20 Hz, the scanner at 2 Hz, set-points) through the acquisition's
RunWriter, which builds /aligned from them and compacts the file as `benchlab run` does. Not timed.

Timed (CPU seconds of this process, best of --repeat): `benchlab.export.export(RUN.h5, OUT.mf4)` (read the run
file, write every group: /aligned, six raw streams, events) and the same export written for /aligned alone (the
whole file still read); the peer is what an asammdf user writes for /aligned: `load_run`,
`MDF(version="4.10").append(frame, units=...)`, `save` with the same compression. Target: like for like
(/aligned) within 1.5x of the peer, and the same samples; the whole-file ratio is printed beside it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
from asammdf import MDF

from benchlab.acquire import RunWriter
from benchlab.export import export
from benchlab.export.content import read_content
from benchlab.export.mdf import COMPRESSION, MDF_VERSION, write_mdf
from benchlab.importing.mdf import numbers
from benchlab.runfile import load_run
from benchlab.runner.devices import bench_layout
from protocols.table1 import table1_schedule
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

sys.path.insert(0, str(Path(__file__).resolve().parent))
from targets import print_target, summarise_targets  # noqa: E402

TARGET_RATIO = 1.5
GEAR_RATIO = 15.0


def stream_rows(run, stream: str, columns: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(times, rows) of one raw stream as the simulated bench delivers it, from the batch run's channels."""
    t = run["time"].to_numpy()
    n = len(t)
    one, zero = np.ones(n), np.zeros(n)
    clamped = run["clutch_state"].to_numpy() > 0.5
    slipping = run["friction_power"].to_numpy() > 0
    values = {
        "can_drive": {"speed": run["engine_speed"], "torque": run["clutch_torque"], "state": one, "fault_code": zero},
        "can_clutch": {"torque": run["clutch_torque"], "position": np.where(clamped, 2.0, 0.0),
                       "clamp_state": np.where(slipping, 1.0, np.where(clamped, 2.0, 0.0)), "state": one,
                       "fault_code": zero},
        "can_load": {"torque": run["load_torque"], "speed": run["clutch_speed"] / GEAR_RATIO, "state": one,
                     "fault_code": zero},
    }.get(stream)
    if values is not None:  # a status frame every 10 ms
        picks = np.arange(n)
    elif stream == "node":  # 20 Hz, no frame during a radio drop-out
        picks = np.arange(0, n, 5)
        picks = picks[np.isfinite(run["T_flywheel_1"].to_numpy()[picks])]
        values = {"seq": np.arange(n) // 5 % 65536, "node_time": t, "supply": 3300.0 + zero, "rssi": -60.0 + zero,
                  "lqi": 200.0 + zero, "flags": zero}
        for k in (1, 2):
            values.update({f"T_flywheel_{k}": run[f"T_flywheel_{k}"], f"status_{k}": zero,
                           f"R_flywheel_{k}": 1000.0 * (1 + 3.9083e-3 * run[f"T_flywheel_{k}"].to_numpy())})
    elif stream == "instrument":  # a scan every 0.5 s
        picks = np.arange(0, n, 50)
        values = {}
        for name in ("T_air", "T_housing", "T_ambient"):
            values.update({name: run[name], f"{name}_ohm": 1000.0 * (1 + 3.9083e-3 * run[name].to_numpy()),
                           f"{name}_status": zero})
    else:  # set-points: one row per change of the commanded engine speed
        picks = np.flatnonzero(np.diff(np.round(run["engine_speed"].to_numpy(), -2), prepend=-1.0) != 0)
        values = {"engine_speed": run["engine_speed"], "clutch_torque": run["clutch_torque"],
                  "clutch_open": (~clamped).astype(float), "load_torque": run["load_torque"]}
    return t[picks], np.column_stack([np.asarray(values[c], dtype=float)[picks] for c in columns])


def make_run(path: Path, hours: float, seed: int) -> None:
    """A `hours` long run file with the simulated bench's raw streams, written by RunWriter (see module doc)."""
    planned = run_schedule(table1_schedule(seed, duration_s=1.25 * hours * 3600.0), ThermalPlant(), seed=seed)
    run = planned.iloc[: int(round(hours * 3600.0 / planned.attrs["dt"])) + 1]  # launches end early: cut to `hours`
    layout = bench_layout(SimulatedBench().bench_config())
    readings = []
    for spec in layout.streams:
        times, rows = stream_rows(run, spec.name, spec.names)
        readings += [(t, spec.name, row) for t, row in zip(times.tolist(), rows.tolist())]
    readings.sort(key=lambda r: r[0])
    writer = RunWriter(path, layout, protocol="table1", planned_s=hours * 3600.0)
    for event in planned.attrs["events"]:
        if event["time"] <= run["time"].iloc[-1]:
            writer.event(event["time"], event["event"], event["cycle"])
    for t, stream, row in readings:
        writer.add(stream, t, row)
        writer.advance(t)
    writer.close("complete")


def peer_aligned_import(run_path: Path, out: Path) -> None:
    """What an asammdf user writes for /aligned: the DataFrame (time as index) appended with its units, saved."""
    frame = load_run(run_path)
    units = frame.attrs["units"]
    mdf = MDF(version=MDF_VERSION)
    mdf.append(frame.set_index("time"), units=units)
    mdf.save(out, overwrite=True, compression=COMPRESSION)
    mdf.close()


def best_cpu(tasks: dict[str, Callable[[], object]], repeat: int) -> dict[str, float]:
    """Best CPU time (s) of each task over `repeat` rounds, the tasks interleaved in every round so that a
    busy spell of the shared machine does not fall on one of them only."""
    best = dict.fromkeys(tasks, float("inf"))
    for _ in range(repeat):
        for name, task in tasks.items():
            start = time.process_time()
            task()
            best[name] = min(best[name], time.process_time() - start)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="a 20 min run, one repeat")
    args = ap.parse_args()
    hours, repeat = (1 / 3, 1) if args.quick else (args.hours, args.repeat)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        run_path, ours, aligned, peer = (Path(tmp) / n for n in ("run.h5", "run.mf4", "aligned.mf4", "peer.mf4"))
        t0 = time.perf_counter()
        make_run(run_path, hours, args.seed)
        content = read_content(run_path)
        print(f"run file: {content.aligned.time[-1] / 3600:.2f} h of Table 1, {run_path.stat().st_size / 1e6:.1f} MB, "
              f"made in {time.perf_counter() - t0:.0f} s; "
              f"rows {({g.path: len(g.time) for g in content.groups})}")
        peer_aligned_import(run_path, peer)  # warm-up: asammdf's and benchlab's imports and caches

        def aligned_only() -> None:
            whole = read_content(run_path)
            write_mdf(replace(whole, groups=whole.groups[:1]), aligned)

        times = best_cpu({"ours": lambda: export(run_path, ours, force=True), "aligned": aligned_only,
                          "peer": lambda: peer_aligned_import(run_path, peer)}, repeat)
        t_ours, t_aligned, t_peer = times["ours"], times["aligned"], times["peer"]
        with MDF(ours) as a, MDF(peer) as b:
            same = all(np.array_equal(numbers(a, name=c.name)[1], b.get(c.name).samples, equal_nan=True)
                       for c in content.aligned.channels)  # ours: NaN under invalidation bits, states as integers
        sizes = {path: path.stat().st_size / 1e6 for path in (ours, aligned, peer)}
    print(f"\nCPU s, best of {repeat}:")
    rows = ((f"benchlab export, whole run file ({len(content.groups)} groups)", t_ours, sizes[ours]),
            (f"benchlab export, /aligned only ({len(content.aligned.channels)} channels)", t_aligned, sizes[aligned]),
            ("peer: asammdf MDF.append(DataFrame), /aligned", t_peer, sizes[peer]))
    for label, seconds, megabytes in rows:
        print(f"  {label:<48}{seconds:7.2f} s {megabytes:7.1f} MB")
    print(f"  ratios to the peer: whole file {t_ours / t_peer:.2f}x, /aligned only {t_aligned / t_peer:.2f}x\n")
    targets = [("/aligned export vs peer", f"{t_aligned / t_peer:.2f}x (<= {TARGET_RATIO:g}x)",
                t_aligned / t_peer <= TARGET_RATIO),
               ("same /aligned as the peer", "identical" if same else "DIFFERENT", same)]
    for target in targets:
        print_target(*target)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    sys.exit(main())
