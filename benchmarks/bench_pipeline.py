"""CPU of the main job, `benchlab pipeline`, stage by stage, beside the floors it cannot go under.

    .venv/bin/python benchmarks/bench_pipeline.py [--repeats N] [--plant reference|paper] [--seed S]

Each repeat runs `benchlab pipeline --out TMP --quiet` in a child process (the job as a user starts it: imports,
three bench runs through the drivers, identify, diagnose with its forked workers, eq. (11), the plate, report, wear,
deploy) and takes its CPU seconds (user + system, the child's own workers included) from the kernel's accounting.
Inside the child each stage of the job (a function of benchlab.commands.pipeline, or a command function it calls)
is timed in CPU seconds where the job enters it; a stage called from inside another counts to the outer one, and
"rest" is what the stages leave (imports, argument parsing, printing).

Peers, measured in the same run:
- the bench stage's floor: python-can's own cost per frame (a can.Message built and written by its BLFWriter,
  benchmarks/python_can_floor.py, as bench_sim_bench.py) times the frames the job's three runs logged (their BLF files'
  object counts): what a stack that builds one python-can object per frame spends on the frames alone;
- the interpreter's floor: `python -c 'import numpy, pandas, h5py, numba, scipy, matplotlib'`, the libraries the
  job needs before it does anything.

Where diagnose's CPU goes: after the repeats, diagnose on the last job's Table 1 run and sweep (the unseen
validation run beside them, as the job calls it) again in a child pinned to one CPU (its candidate fits then run
one after another in that process, where they can be timed), its CPU split by what the engine was doing, each
second counted to the innermost step: the score test of every candidate, the screening fits, the polishing fits
and their scouts from the neutral start, the held-out fold fits, leave-one-run-out, the multistart fits (baseline,
refit after an acceptance), the evidence, the identifiability and unseen-run judgement, and the rest.

Target (issue 47): the whole job <= 60 s CPU on a quiet machine, the median over the repeats (printed with the
range: the same job on this shared machine moved by 57-75 s within one hour). Exit code 1 if it is missed. The bench
stage's share of its floor is printed, not a target: it counts reading each run back and describing it, and the
simulated bench's own target (>= 0.8 of python-can's bound on the reference plant) is bench_sim_bench.py's.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from python_can_floor import python_can_floor_us  # noqa: E402
from targets import load, print_target, summarise_targets  # noqa: E402

TARGET_CPU_S = 60.0

# The child: the pipeline in process, each stage's CPU (outermost call only) written as JSON to argv[1].
_CHILD = r"""
import importlib, json, resource, sys
def cpu():
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
spent, inside = {}, [False]
def timed(module, name, label):
    home = importlib.import_module(module)
    original = getattr(home, name)
    def stage(*args, **kwargs):
        if inside[0]:
            return original(*args, **kwargs)
        inside[0], started = True, cpu()
        try:
            return original(*args, **kwargs)
        finally:
            spent[label] = spent.get(label, 0.0) + cpu() - started
            inside[0] = False
    setattr(home, name, stage)
STAGES = [
    ("benchlab.commands.pipeline", "_bench_run", "bench runs (Table 1, validation, sweep)"),
    ("benchlab.identify.api", "identify", "identify linear + nonlinear"),
    ("benchlab.commands.pipeline", "_sweep_comparison", "eq. (11) against the sweep"),
    ("benchlab.commands.pipeline", "_diagnose", "diagnose (with its page)"),
    ("benchlab.commands.pipeline", "_eq11_errors", "eq. (11) of the diagnosed model"),
    ("benchlab.commands.pipeline", "_plate", "plate: observer and bands"),
    ("benchlab.report", "write_report", "report page"),
    ("benchlab.wear", "analyse_wear", "wear"),
    ("benchlab.wear.plot", "plot_wear", "wear"),
    ("benchlab.commands.pipeline", "_deploy", "deploy (C module, proven)"),
    ("benchlab.report.index", "cooldown_scores", "cool-down scores, index"),
    ("benchlab.report.index", "write_index", "cool-down scores, index"),
]
for module, name, label in STAGES:
    timed(module, name, label)
from benchlab.cli import main
started = cpu()
code = main(["pipeline", "--out", sys.argv[2], "--quiet", "--force", *sys.argv[3:]])
json.dump({"code": code, "stages": spent, "in_process": cpu() - started}, open(sys.argv[1], "w"))
"""


# The child for diagnose's own breakdown: argv[1] the JSON to write, argv[2] the job's directory.
_DIAGNOSE_CHILD = r"""
import json, os, resource, sys
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one CPU: the candidate fits run in this process
def cpu():
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime
import benchlab.diagnose.engine as engine
from benchlab.runfile import load_run
stack, spent, mark = ["rest (library, re-checks, predictions)"], {}, [0.0]
def switch():
    now = cpu()
    spent[stack[-1]] = spent.get(stack[-1], 0.0) + now - mark[0]
    mark[0] = now
def labelled(name, label):
    original = getattr(engine, name)
    def step(*args, **kwargs):
        switch()
        inner = label(kwargs) if callable(label) else label
        stack.append(inner)
        try:
            return original(*args, **kwargs)
        finally:
            switch()
            stack.pop()
    setattr(engine, name, step)
labelled("_score", "score test of every candidate")
labelled("_screen", "screening fits")
labelled("_polished", "polishing fits")
labelled("_held_out", "held-out fold fits")
labelled("_held_out_runs", "leave-one-run-out fits")
labelled("fit_multistart", "multistart fits (baseline, refits)")
labelled("baseline_evidence", "evidence")
labelled("_judge", "identifiability, unseen runs")
labelled("fit", lambda kwargs: "polishing: scouts from the neutral start"
         if stack[-1] == "polishing fits" and kwargs.get("max_nfev") == engine.SCOUT_NFEV else stack[-1])
from benchlab.commands.pipeline import DIAGNOSED_RUNS  # the runs the job diagnoses; the validation run unseen
runs = [load_run(os.path.join(sys.argv[2], name + ".h5")) for name in DIAGNOSED_RUNS]
unseen = [load_run(os.path.join(sys.argv[2], "validation.h5"))]
mark[0] = cpu()
diagnosis = engine.diagnose_runs(runs, "nonlinear", validate=unseen)
switch()
json.dump({"spent": spent, "findings": [f.candidate.key for f in diagnosis.findings]}, open(sys.argv[1], "w"))
"""


def children_cpu() -> float:
    """CPU seconds (user + system) of this process's finished children so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def child(argv: list[str]) -> float:
    """CPU seconds of `python argv…` run to its end (its printing discarded: the job's lines are not the figure)."""
    before = children_cpu()
    subprocess.run([sys.executable, *argv], check=True, cwd=Path(__file__).resolve().parent.parent,
                   stdout=subprocess.DEVNULL)
    return children_cpu() - before


def frames_logged(out: Path) -> int:
    """CAN frames the job's runs logged: the object counts in their BLF files' headers."""
    import can

    total = 0
    for blf in sorted(out.glob("*.blf")):
        reader = can.BLFReader(str(blf))
        total += reader.object_count
        reader.stop()
    return total


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--plant", choices=("reference", "paper"), default="reference")
    parser.add_argument("--seed", type=int, default=None, help="the pipeline's --seed (its default otherwise)")
    args = parser.parse_args()
    started = time.perf_counter()
    extra = ["--plant", args.plant] + ([] if args.seed is None else ["--seed", str(args.seed)])
    print(f"bench_pipeline: `benchlab pipeline --plant {args.plant}`, {args.repeats} repeats, {load()}")
    totals, stage_runs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        for repeat in range(args.repeats):
            report, out = tmp_path / "stages.json", tmp_path / "out"
            total = child(["-c", _CHILD, str(report), str(out), *extra])
            result = json.loads(report.read_text())
            if result["code"] != 0:
                raise SystemExit(f"benchlab pipeline exited {result['code']}")
            totals.append(total)
            stage_runs.append(result)
            print(f"  repeat {repeat + 1}: {total:6.1f} s CPU ({result['in_process']:.1f} s inside the command)",
                  flush=True)
        frames = frames_logged(tmp_path / "out")
        child(["-c", _DIAGNOSE_CHILD, str(tmp_path / "diagnose.json"), str(tmp_path / "out")])
        diagnose = json.loads((tmp_path / "diagnose.json").read_text())
        floor_us = statistics.median(python_can_floor_us(tmp_path / "floor.blf") for _ in range(3))
    imports_s = statistics.median(
        child(["-c", "import numpy, pandas, h5py, numba, scipy, matplotlib"]) for _ in range(3))
    total = statistics.median(totals)
    labels = list(dict.fromkeys(label for run in stage_runs for label in run["stages"]))
    stages = {label: statistics.median(run["stages"].get(label, 0.0) for run in stage_runs) for label in labels}
    rest = total - sum(stages.values())
    bench_floor_s = frames * floor_us * 1e-6
    print(f"\n  {'stage':<42}{'CPU s':>8}{'share':>8}")
    for label, seconds in sorted(stages.items(), key=lambda item: -item[1]):
        print(f"  {label:<42}{seconds:8.1f}{100 * seconds / total:7.0f} %")
    print(f"  {'rest (imports, arguments, printing)':<42}{rest:8.1f}{100 * rest / total:7.0f} %")
    print(f"  {'the whole job (median)':<42}{total:8.1f}   (repeats {min(totals):.1f}-{max(totals):.1f})")
    one_cpu = sum(diagnose["spent"].values())
    print(f"\n  diagnose alone, pinned to one CPU ({one_cpu:.1f} s; findings: {', '.join(diagnose['findings']) or 'none'}):")
    for label, seconds in sorted(diagnose["spent"].items(), key=lambda item: -item[1]):
        print(f"    {label:<44}{seconds:8.1f}{100 * seconds / one_cpu:7.0f} %")
    bench_s = stages.get("bench runs (Table 1, validation, sweep)", float("nan"))
    share = bench_floor_s / bench_s
    print(f"\n  peers, same run:")
    print(f"  python-can alone for the job's {frames:,} CAN frames ({floor_us:.2f} us/frame: Message + BLFWriter)"
          f" {bench_floor_s:6.1f} s; the bench stage is at {share:.2f} of it")
    print(f"  the interpreter and the six libraries it imports             {imports_s:6.1f} s")
    print(f"  the job beyond those two floors                              {total - bench_floor_s - imports_s:6.1f} s")
    targets = [("pipeline CPU", f"{total:.1f} s <= {TARGET_CPU_S:.0f} s", total <= TARGET_CPU_S)]
    print()
    for name, text, ok in targets:
        print_target(name, text, ok)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    sys.exit(main())
