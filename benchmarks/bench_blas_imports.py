"""CPU cost of a 2 h identification under the import orders and BLAS settings a caller may bring.

    .venv/bin/python benchmarks/bench_blas_imports.py [--quick] [--seed S]

The run (simulated Table 1, dt = 10 ms, 2 h; --quick: 20 min) is made once and written as a run file.
Each case is a fresh interpreter that imports as the case says, loads the run with
`benchlab.runfile.load_run`, warms numba on a 10-min slice, then times `identify([run], "nonlinear")`
in CPU seconds (process_time: all threads) and reads threadpoolctl's BLAS thread counts inside the fit.
Peer: the plain case, `import benchlab` first with no thread variables set. Target: every case within
1.3x of the peer's CPU time, one BLAS thread during every fit.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_identify import simulated_run  # noqa: E402 - benchmarks/, beside this script
from targets import load, print_target, summarise_targets  # noqa: E402

from benchlab.runfile import write_run  # noqa: E402

TARGET_VS_PEER = 1.3
NUMPY_FIRST = "import numpy, scipy\nfrom benchlab.runfile import load_run\n"
BENCHLAB_FIRST = "import benchlab\nfrom benchlab.runfile import load_run\n"
CASES = {  # name: (imports, thread variables); OPENBLAS = OPENBLAS_NUM_THREADS
    "benchlab first (peer)": (BENCHLAB_FIRST, {}),
    "numpy+scipy first": (NUMPY_FIRST, {}),
    "np+scipy first, OPENBLAS=''": (NUMPY_FIRST, {"OPENBLAS_NUM_THREADS": ""}),
    "np+scipy first, OPENBLAS=2": (NUMPY_FIRST, {"OPENBLAS_NUM_THREADS": "2"}),
}
CASE_BODY = """
import json, sys, time
import threadpoolctl
import benchlab.identify.fit  # the module, not the function the package exports under that name
from benchlab.identify.api import identify

fit_module = sys.modules["benchlab.identify.fit"]
least_squares, seen = fit_module.least_squares, set()

def spy(*args, **kwargs):
    seen.update(i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas")
    return least_squares(*args, **kwargs)

fit_module.least_squares = spy
run = load_run(sys.argv[1])
warm = run.iloc[:60000].reset_index(drop=True)
warm.attrs = dict(run.attrs)
identify([warm], "nonlinear")
seen.clear()
c0 = time.process_time()
identify([run], "nonlinear")
print(json.dumps({"cpu_s": time.process_time() - c0, "threads_in_fit": sorted(seen)}))
"""


def run_case(imports: str, variables: dict[str, str], path: Path) -> dict:
    """One fresh interpreter: its imports, then the timed identification; CPU s and BLAS threads seen."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")} | variables
    out = subprocess.run([sys.executable, "-c", imports + CASE_BODY, str(path)], env=env, capture_output=True,
                         text=True, check=True).stdout
    return json.loads(out.splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 20-min run instead of 2 h")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    started = time.perf_counter()
    duration = 1200.0 if args.quick else 7200.0
    print(f"bench_blas_imports: {duration / 3600:.2g} h run, {load()}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.h5"
        run = simulated_run(args.seed, duration)
        write_run(path, run, run.attrs["dt"], protocol="table1")
        results = {name: run_case(imports, variables, path) for name, (imports, variables) in CASES.items()}
    peer = results["benchlab first (peer)"]["cpu_s"]
    targets = []
    for name, r in results.items():
        print(f"   {name:<32}{r['cpu_s']:6.1f} s CPU  {r['cpu_s'] / peer:4.2f}x  BLAS threads in fit {r['threads_in_fit']}")
        ok = r["cpu_s"] <= TARGET_VS_PEER * peer and r["threads_in_fit"] == [1]
        targets.append((name, f"{r['cpu_s'] / peer:.2f}x, {r['threads_in_fit']}", ok))
    print()
    for target in targets:
        print_target(*target)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    sys.exit(main())
