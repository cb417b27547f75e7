"""CPU of the first `benchlab run` after a fresh install (numba's cache empty) against a warm one.

    .venv/bin/python benchmarks/bench_first_run.py [--duration S | --default-run] [--repeats N] [--kernels]

A fresh install has no numba cache: every kernel the run calls is compiled at first use. Here each child gets
its own empty NUMBA_CACHE_DIR for the cold run (what `pip install` leaves), then the same directory again for the
warm runs (what every later run sees). The figure is CPU seconds (user + system) of the child `benchlab run
table1 --bench sim --duration S` (`--default-run`: without --duration, the 2 h plan a user's first run draws);
warm is the median of N. Peer: the warm run. Target: cold <= 2x warm. Exit code 1 if the target is missed.

Each run also counts numba's compiles (its `numba:compile` events: the project's kernels and the numba overloads
they pull in, each signature once) and the CPU inside them; `--kernels` lists them per kernel for the cold run.
The children import `benchlab` from the working directory first, so running this from another checkout's root
measures that checkout (its `benchlab`, `drivers`, `sim_bench`) with this interpreter.
"""

from __future__ import annotations

import argparse
import json
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

# The child: `benchlab ARGV` with every numba compile noted (kernel, signature, CPU s inside it, nested ones
# included in their caller's time and listed on their own), written as JSON to the file named by argv[1].
_CHILD = r"""
import json, sys, time
from numba.core import event

compiles, open_at = [], []

class Noted(event.Listener):
    def on_start(self, ev):
        open_at.append(time.process_time())

    def on_end(self, ev):
        cpu = time.process_time() - open_at.pop()
        func = ev.data["dispatcher"].py_func
        compiles.append([len(open_at), f"{func.__module__}.{func.__qualname__}", str(ev.data["args"]), cpu])

event.register("numba:compile", Noted())
from benchlab.cli import main
code = main(sys.argv[2:])
with open(sys.argv[1], "w") as f:
    json.dump(compiles, f)
sys.exit(code)
"""


def child_run(argv: list[str], cache: str, noted: str) -> tuple[float, list]:
    """CPU seconds of one child `benchlab ARGV` with numba's cache in `cache`, and its compiles (depth, kernel,
    signature, CPU s)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    subprocess.run([sys.executable, "-c", _CHILD, noted, *argv], check=True, env=env, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(noted) as f:
        compiles = json.load(f)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), compiles


def compile_summary(compiles: list) -> str:
    """How many compiles, of how many distinct functions (the project's kernels apart), and their CPU."""
    own = {name for _, name, _, _ in compiles if not name.startswith("numba.")}
    cpu = sum(c for depth, _, _, c in compiles if depth == 0)
    return (f"{len(compiles)} compiles ({len(own)} project kernels, "
            f"{len(compiles) - sum(1 for _, n, _, _ in compiles if n in own)} numba overloads), {cpu:.1f} s CPU")


def list_kernels(compiles: list) -> None:
    """Per compiled function: signatures compiled and CPU inside (nested compiles included), largest first."""
    per: dict[str, list[float]] = {}
    for _, name, _, cpu in compiles:
        per.setdefault(name, []).append(cpu)
    for name, cpus in sorted(per.items(), key=lambda item: -sum(item[1])):
        print(f"      {sum(cpus):6.2f} s  {len(cpus):>2} x  {name}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=120.0, help="simulated seconds of the run")
    parser.add_argument("--default-run", action="store_true", help="no --duration: the run a user's first one is")
    parser.add_argument("--repeats", type=int, default=3, help="warm runs (median taken)")
    parser.add_argument("--kernels", action="store_true", help="list the cold run's compiles per kernel")
    args = parser.parse_args()
    started = time.perf_counter()
    print(f"load average at the start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; benchlab from {os.getcwd()}")
    shown = "" if args.default_run else f" --duration {args.duration:g}"
    with tempfile.TemporaryDirectory() as tmp:
        cache, noted = os.path.join(tmp, "numba-cache"), os.path.join(tmp, "compiles.json")
        os.makedirs(cache)

        def argv(i: int) -> list[str]:
            return ["run", "table1", "--bench", "sim", *shown.split(), "--out", os.path.join(tmp, f"run{i}.h5")]
        cold, cold_compiles = child_run(argv(0), cache, noted)
        warm_runs = [child_run(argv(i + 1), cache, noted) for i in range(args.repeats)]
    warm = statistics.median(cpu for cpu, _ in warm_runs)
    ratio = cold / warm
    print(f"benchlab run table1 --bench sim{shown}")
    print(f"   first run, empty numba cache   {cold:>8.1f} s CPU; {compile_summary(cold_compiles)}")
    print(f"   warm run (median of {args.repeats})        {warm:>8.1f} s CPU; "
          f"{compile_summary(warm_runs[0][1])}")
    if args.kernels:
        list_kernels(cold_compiles)
    text = f"{ratio:.1f}x <= {TARGET:.0f}x"
    print_target("first / warm", text, ratio <= TARGET)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return summarise_targets([("first / warm", text, ratio <= TARGET)], started)


if __name__ == "__main__":
    sys.exit(main())
