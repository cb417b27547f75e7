"""CPU of the first `benchlab run` after a fresh install (numba's cache empty) against a warm one.

    .venv/bin/python benchmarks/bench_first_run.py [--duration S] [--repeats N]

A fresh install has no numba cache: every kernel the run calls is compiled at first use. Here each child gets
its own empty NUMBA_CACHE_DIR for the cold run (what `pip install` leaves), then the same directory again for the
warm runs (what every later run sees). The figure is CPU seconds (user + system) of the child `benchlab run
table1 --bench sim --duration S`; warm is the median of N. Peer: the warm run. Target: cold <= 2x warm.
Exit code 1 if the target is missed.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from targets import print_target, summarise_targets  # noqa: E402

TARGET = 2.0


def child_cpu_s(argv: list[str], cache: str) -> float:
    """CPU seconds of one child `benchlab ARGV` with numba's cache in `cache`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    subprocess.run([sys.executable, "-m", "benchlab.cli", *argv], check=True, env=env, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=120.0, help="simulated seconds of the run")
    parser.add_argument("--repeats", type=int, default=3, help="warm runs (median taken)")
    args = parser.parse_args()
    started = time.perf_counter()
    print(f"load average at the start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        cache = os.path.join(tmp, "numba-cache")
        os.makedirs(cache)

        def argv(i: int) -> list[str]:
            return ["run", "table1", "--bench", "sim", "--duration", str(args.duration),
                    "--out", os.path.join(tmp, f"run{i}.h5")]
        cold = child_cpu_s(argv(0), cache)
        warm = statistics.median(child_cpu_s(argv(i + 1), cache) for i in range(args.repeats))
    ratio = cold / warm
    print(f"benchlab run table1 --bench sim --duration {args.duration:g}")
    print(f"   first run, empty numba cache   {cold:>8.1f} s CPU ({args.duration / cold:.0f}x real time)")
    print(f"   warm run (median of {args.repeats})        {warm:>8.1f} s CPU ({args.duration / warm:.0f}x real time)")
    text = f"{ratio:.1f}x <= {TARGET:.0f}x"
    print_target("first / warm", text, ratio <= TARGET)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return summarise_targets([("first / warm", text, ratio <= TARGET)], started)


if __name__ == "__main__":
    sys.exit(main())
