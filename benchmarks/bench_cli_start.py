"""CPU cost of starting `benchlab`: `--help` and light commands' help, this checkout against another one.

    .venv/bin/python benchmarks/bench_cli_start.py BEFORE_DIR [--repeat N]

BEFORE_DIR is a checkout of the code to compare with (e.g. `git archive main | tar -x -C /tmp/main`); both
trees run with this interpreter and its packages, `python -m benchlab.cli ARGS` with the tree as working
directory (so its `benchlab` is the one imported). The two trees alternate, N times each per command after one
warm-up each (byte-code caches written); the figure is the median CPU time (user + system) of the child
process. Peer: BEFORE_DIR; the ratio is before / this checkout.

`--simulate RUN.h5 PARAMS.json` adds `benchlab simulate RUN.h5 --params PARAMS.json --out ...` (a whole command:
start-up, reading the run, the simulation, writing /simulated; issue 36's target: <= 0.6 s CPU on a 2 h run).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
COMMANDS = (["--help"], ["watch", "--help"], ["probe", "--help"])


def child_cpu_s(tree: Path, argv: list[str]) -> float:
    """CPU seconds (user + system) of one `python -m benchlab.cli ARGV` run in `tree`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-m", "benchlab.cli", *argv], cwd=tree, check=True, stdout=subprocess.DEVNULL,
                   env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path, help="checkout to compare with (the peer)")
    parser.add_argument("--repeat", type=int, default=7, help="runs per tree and command (median taken)")
    parser.add_argument("--simulate", nargs=2, metavar=("RUN", "PARAMS"), help="also time `benchlab simulate`")
    args = parser.parse_args()
    commands = list(COMMANDS)
    if args.simulate:
        run, params = (str(Path(p).resolve()) for p in args.simulate)
        out = str(Path(tempfile.mkdtemp()) / "sim.h5")
        commands.append(["simulate", run, "--params", params, "--out", out, "--force"])
    trees = {"before": args.before.resolve(), "after": HERE}
    print(f"load average at the start: {os.getloadavg()[0]:.2f}")
    print(f"{'command':<24} {'before (s)':>10} {'after (s)':>10} {'ratio':>7}")
    for argv in commands:
        cpu: dict[str, list[float]] = {name: [] for name in trees}
        for name, tree in trees.items():
            child_cpu_s(tree, argv)  # warm-up: byte-code caches
        for _ in range(args.repeat):
            for name, tree in trees.items():
                cpu[name].append(child_cpu_s(tree, argv))
        before, after = statistics.median(cpu["before"]), statistics.median(cpu["after"])
        shown = "benchlab simulate RUN" if argv[0] == "simulate" else "benchlab " + " ".join(argv)
        print(f"{shown:<24} {before:>10.3f} {after:>10.3f} {before / after:>6.1f}x")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
