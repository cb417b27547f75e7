"""CPU cost of starting `benchlab`: `--help` and light commands' help, this checkout against another one.

    .venv/bin/python benchmarks/bench_cli_start.py BEFORE_DIR [--repeat N]

BEFORE_DIR is a checkout of the code to compare with (e.g. `git archive main | tar -x -C /tmp/main`); both
trees run with this interpreter and its packages, `python -m benchlab.cli ARGS` with the tree as working
directory (so its `benchlab` is the one imported). The two trees alternate, N times each per command after one
warm-up each (byte-code caches written); the figure is the median CPU time (user + system) of the child
process. Peer: BEFORE_DIR; the ratio is before / this checkout.

`--simulate RUN.h5 PARAMS.json` adds `benchlab simulate RUN.h5 --params PARAMS.json --out ...` (a whole command:
start-up, reading the run, the simulation, writing /simulated), and beside it its floor (issue 47), measured the same
way in a child process: `import numpy, pandas, h5py, numba` and the command's own I/O (reading the channels it
reads, copying /aligned and writing as many compressed columns as it writes), nothing simulated. Target: simulate
<= 1.5x that floor (exit 1 if missed). benchlab freezes the garbage collector when its main returns (its passes at
the interpreter's exit would walk every object of the four libraries: `benchlab.cli.main_of_process`); the floor
is also shown frozen alike, like for like, with the ratio to it.
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
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
COMMANDS = (["--help"], ["watch", "--help"], ["probe", "--help"])


def child_cpu_s(tree: Path, argv: list[str], module: bool = True) -> float:
    """CPU seconds (user + system) of one `python -m benchlab.cli ARGV` run in `tree` (`python ARGV` if not
    `module`)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, *(["-m", "benchlab.cli"] if module else []), *argv], cwd=tree, check=True,
                   stdout=subprocess.DEVNULL,
                   env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: the floor of `benchlab simulate`: the four imports, then the command's own reading and writing of run files
SIMULATE_FLOOR = """
import sys, json
import numpy, pandas, h5py, numba
from benchlab.runfile.compressed import compressed_dataset
run, out, channels, written = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), int(sys.argv[4])
with h5py.File(run, "r") as src:
    columns = {name: src["aligned"][name][()] for name in channels}
    with h5py.File(out, "w") as f:
        f.attrs.update(src.attrs)
        src.copy(src["aligned"], f, "aligned")
        group = f.create_group("simulated")
        for i in range(written + 1):  # its time, then each simulated channel
            compressed_dataset(group, f"c{i}", columns["time"] + i)
if sys.argv[5:] == ["frozen"]:
    import gc
    gc.freeze()
"""


def floor_argv(run: str, params: str, out: str) -> list[str]:
    """The floor's command line: the channels `benchlab simulate` reads from the run and how many it writes."""
    from benchlab.model.options import load_model_params
    from benchlab.model.runs import load_runs

    model = load_model_params(params, None)
    measured = load_runs([run], model.definition, model, params, model_channels_only=True)[0]
    return ["-c", SIMULATE_FLOOR, run, out, json.dumps(list(measured.columns)), str(len(model.network.state_names))]


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
        floor = floor_argv(run, params, str(Path(out).with_name("floor.h5")))
    trees = {"before": args.before.resolve(), "after": HERE}
    missed = False
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
        if argv[0] == "simulate":
            floors: dict[str, list[float]] = {"plain": [], "frozen": []}
            for kind in floors:
                child_cpu_s(HERE, [*floor, kind], module=False)  # warm-up
            for _ in range(args.repeat):
                for kind, times in floors.items():
                    times.append(child_cpu_s(HERE, [*floor, kind], module=False))
            floor_s = statistics.median(floors["plain"])
            ratio = after / floor_s
            print(f"{'its floor (imports+I/O)':<24} {'':>10} {floor_s:>10.3f} {ratio:>6.2f}x  (simulate / floor, target "
                  f"<= 1.5x: {'ok' if ratio <= 1.5 else 'MISSED'})")
            frozen_s = statistics.median(floors["frozen"])
            print(f"{'floor, frozen at exit':<24} {'':>10} {frozen_s:>10.3f} {after / frozen_s:>6.2f}x  (like for like)")
            missed = ratio > 1.5
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    raise SystemExit(1 if missed else 0)


if __name__ == "__main__":
    main()
