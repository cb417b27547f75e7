"""Cost of one update of the live page (`benchlab watch`) at 10 min, 1 h and 10 h of run, beside a naive peer.

    .venv/bin/python benchmarks/bench_watch.py [--updates N] [--hours H,H,...]

For each run length a run file is written the way `benchlab run` writes it, by RunWriter, still open and
`running` (the batch simulator's Table 1 run at 10 ms, its /aligned channels fed to the writer as one stream
read every 10 ms, its schedule stored). The watcher (benchlab.watch.live.LiveRun) opens it and catches up
once; then, N times, the writer adds one second of data and flushes (not timed) and one page update is timed
in CPU time: read what is new, answer with the status, the buckets from the page's last one on and the new
events, JSON-encoded, as the server sends it. Two views: the whole run (pyramid levels) and the last
10 minutes (buckets finer than the pyramid's, computed from the file). The naive peer re-reads the whole valid
/aligned with h5py at each update (and does not even decimate it). Medians; the ratio is peer / ours.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from benchlab.acquire import AlignedSource, Layout, RunWriter, StreamSpec
from benchlab.runfile import ALIGNED_UNITS
from benchlab.runner.engine import STATE_FIELDS
from benchlab.watch.live import LiveRun
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule
from targets import load, print_target, summarise_targets  # benchmarks/targets.py, beside this script

WIDTH = 1200  # px of the page's plots
TIMED_S = 60  # the last minute of each run is written while the updates are timed
FLAT_FACTOR = 2.0  # an update at 10 h may cost at most this times one at 10 min
PEER_RATIO_10H = 50.0  # and at least this much cheaper than re-reading /aligned (first measured: 115x)


def write_until(writer: RunWriter, times: np.ndarray, values: np.ndarray, start: int, stop: int) -> None:
    """Feed grid rows [start, stop) of the batch run to the writer as readings, one flush per second of data."""
    for k in range(start, stop):
        writer.add("grid", float(times[k]), values[k].tolist())
        if k % 9000 == 0:  # an event every 90 s (a Table 1 cycle), for the events part of each update
            writer.event(float(times[k]), "cycle_start", k // 9000, "")
        writer.advance(float(times[k]))


def make_run(path: Path, hours: float) -> tuple[RunWriter, np.ndarray, np.ndarray, int]:
    """A run file of `hours` written by RunWriter and left open; (writer, grid times, values, rows written)."""
    duration = hours * 3600.0
    # a Table 1 schedule plans its launches at their longest: ask for more and keep what is needed
    schedule = table1_schedule(1, duration_s=1.2 * duration + 4 * TIMED_S)
    frame = run_schedule(schedule, ThermalPlant(), seed=1)
    names = [c for c in frame.columns if c != "time"]
    layout = Layout(streams=(StreamSpec("grid", tuple((n, ALIGNED_UNITS[n]) for n in names), 100.0, 0.015),),
                    sources=tuple(AlignedSource(n, "grid", n) for n in names),
                    aligned_units={n: ALIGNED_UNITS[n] for n in names})
    writer = RunWriter(path, layout, protocol="table1", planned_s=duration + 2 * TIMED_S,
                       schedule=[s.as_dict() for s in schedule], state_fields=STATE_FIELDS)
    writer.state.update(cycle=0, next_step=0, held=0)
    rows = int(round(duration / layout.dt))
    if len(frame) < rows + 2 * TIMED_S * 100:
        raise RuntimeError(f"the batch run holds {len(frame)} rows, {rows + 2 * TIMED_S * 100} needed")
    times, values = frame["time"].to_numpy(), frame[names].to_numpy()
    write_until(writer, times, values, 0, rows)
    return writer, times, values, rows


def length(hours: float) -> str:
    return f"{hours * 60:g} min" if hours < 1 else f"{hours:g} h"


def cpu(fn) -> tuple[float, object]:
    start = time.process_time()
    out = fn()
    return time.process_time() - start, out


class Page:
    """What a page holds between updates (as watch.js keeps it): its span, level, buckets held, events held."""

    def __init__(self, live: LiveRun, span_s: float) -> None:
        self.live, self.span_s = live, span_s
        self.level: int | None = None
        self.have = self.events = 0
        self.update()  # the page's first load (not timed)

    def update(self) -> tuple[float, int]:
        """One update: (CPU seconds, bytes of the answer)."""
        elapsed, body = cpu(lambda: json.dumps(self.live.update(
            width=WIDTH, span_s=self.span_s, level=self.level, have=self.have, events_from=self.events)))
        answer = json.loads(body)
        self.level, self.have = answer["series"]["level"], answer["series"]["first"] + answer["series"]["count"]
        self.events += len(answer["events"]["items"])
        return elapsed, len(body)


def naive(path: Path, rows: int) -> float:
    """The peer: open the file and read every /aligned channel up to `rows` with h5py."""
    def read() -> int:
        with h5py.File(path, "r") as f:
            return sum(ds[:rows].size for ds in f["aligned"].values())
    return cpu(read)[0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=25, help="timed updates per view and run length")
    parser.add_argument("--hours", default=f"{1 / 6},1,10", help="run lengths in hours")
    args = parser.parse_args()
    started = time.perf_counter()
    print(f"bench_watch: one page update, {WIDTH} px, one second of new data each; {load()}")
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-watch-") as tmp:
        for hours in (float(h) for h in args.hours.split(",")):
            path = Path(tmp) / f"run-{hours:g}h.h5"
            wall = time.perf_counter()
            writer, times, values, row = make_run(path, hours)
            made = time.perf_counter() - wall
            catch_up, live = cpu(lambda: LiveRun(path))
            first, _ = cpu(lambda: live.update(width=WIDTH))
            pages = {"whole": Page(live, 0.0), "recent": Page(live, 600.0)}
            costs: dict[str, list[tuple[float, int]]] = {name: [] for name in pages}
            for _ in range(args.updates):  # the two views take turns, one second of new data before each update
                for name, page in pages.items():
                    write_until(writer, times, values, row, row + 100)
                    row += 100
                    costs[name].append(page.update())
            whole, whole_bytes = zip(*costs["whole"])
            recent, recent_bytes = zip(*costs["recent"])
            peer = [naive(path, live.rows) for _ in range(5)]
            live.close()
            writer.close("complete")  # the run ends (not timed): the file is compacted, the mapping let go
            r = {"hours": hours, "rows": row, "made_s": made, "catch_up_ms": 1e3 * (catch_up + first),
                 "whole_ms": 1e3 * statistics.median(whole), "recent_ms": 1e3 * statistics.median(recent),
                 "whole_kb": statistics.median(whole_bytes) / 1e3, "recent_kb": statistics.median(recent_bytes) / 1e3,
                 "peer_ms": 1e3 * statistics.median(peer), "mb": path.stat().st_size / 1e6}
            r["ratio"] = r["peer_ms"] / r["whole_ms"]
            results.append(r)
            print(f"  {length(hours):>6}  {row:>9,} rows  file {r['mb']:6.0f} MB (made in {made:4.0f} s)  "
                  f"first open + catch-up {r['catch_up_ms']:8.1f} ms  update: whole run {r['whole_ms']:6.3f} ms "
                  f"({r['whole_kb']:.1f} kB), last 10 min {r['recent_ms']:6.3f} ms ({r['recent_kb']:.1f} kB)  "
                  f"naive re-read {r['peer_ms']:8.1f} ms  ratio {r['ratio']:7.0f}x")
    print(f"\n| run | rows | page update, whole run | page update, last 10 min | naive re-read of /aligned | ratio |"
          f" first open + catch-up |\n| --- | --- | --- | --- | --- | --- | --- |")
    for r in results:
        print(f"| {length(r['hours'])} | {r['rows']:,} | {r['whole_ms']:.2f} ms CPU ({r['whole_kb']:.1f} kB) | "
              f"{r['recent_ms']:.2f} ms ({r['recent_kb']:.1f} kB) | {r['peer_ms']:.1f} ms | {r['ratio']:,.0f}x | "
              f"{r['catch_up_ms']:,.0f} ms |")
    shortest, longest = results[0], results[-1]
    span = f"{length(longest['hours'])} / {length(shortest['hours'])}"
    targets = [(f"flat, whole run {span}", f"{longest['whole_ms'] / shortest['whole_ms']:.2f}x (<= {FLAT_FACTOR:g}x)",
                longest["whole_ms"] <= FLAT_FACTOR * shortest["whole_ms"]),
               (f"flat, 10 min {span}", f"{longest['recent_ms'] / shortest['recent_ms']:.2f}x (<= {FLAT_FACTOR:g}x)",
                longest["recent_ms"] <= FLAT_FACTOR * shortest["recent_ms"]),
               (f"naive / ours at {length(longest['hours'])}", f"{longest['ratio']:.0f}x (>= {PEER_RATIO_10H:g}x)",
                longest["ratio"] >= PEER_RATIO_10H)]
    print()
    for target in targets:
        print_target(*target)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    raise SystemExit(main())
