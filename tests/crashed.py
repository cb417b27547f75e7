"""Run files as a crash or an abort leaves them, for the tests: RunWriter writes in a child process that is then
killed (`write_then_kill` runs this file as the child; the child reads its job, pickled, from stdin), or a run on the
simulated bench stops on an interlock (`abort_on_silent_load`).
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

CHILD_TIMEOUT_S = 300.0  # a guard against a hung child, not a speed check


def abort_on_silent_load(out: Path, steps: Sequence[Any]) -> tuple[int, Any]:
    """Run `steps` on the simulated bench with the load controller falling silent at 3 s and interlocks set to
    abort: the run stops in its first step, resumable. Returns execute()'s (exit code, summary)."""
    from benchlab.runner.session import RunRequest, execute
    from protocols.limits import BenchLimits
    from sim_bench.bench import SimulatedBench
    from sim_bench.faults import Fault

    sim = SimulatedBench(faults=[Fault(3.0, "controller_silent", target="load")], options={"dropouts": False},
                         limits=BenchLimits(on_interlock="abort"))
    return execute(RunRequest("custom", out, steps=tuple(steps), bench=sim, install_signals=False))


def write_then_kill(path: "str | os.PathLike[str]", layout: Any, calls: Sequence[tuple[Any, ...]],
                    **writer_options: Any) -> int:
    """Open a RunWriter(path, layout, **writer_options) in a child process, make the `calls` on it ((method,
    arguments) or (method, arguments, keyword arguments): "add", "event", "advance", "flush") and kill the child
    with SIGKILL: nothing is closed or compacted, the file stays "running" with what the writer had put into
    it, as after a crash.

    Returns the writer's /aligned rows at the kill.
    """
    job = pickle.dumps((str(path), layout, writer_options, list(calls)))
    child = subprocess.run([sys.executable, str(Path(__file__).resolve())], input=job, capture_output=True,
                           timeout=CHILD_TIMEOUT_S, check=False)
    if child.returncode != -signal.SIGKILL:
        raise AssertionError(f"the writing child ended with {child.returncode}, not killed: "
                             f"{child.stderr.decode(errors='replace')}")
    return int(child.stdout)


def _child() -> None:
    """Do the job on stdin, print the writer's rows, then die by SIGKILL (no atexit, no finaliser runs)."""
    from benchlab.acquire import RunWriter

    path, layout, options, calls = pickle.loads(sys.stdin.buffer.read())
    writer = RunWriter(path, layout, **options)
    for method, args, *keywords in calls:
        getattr(writer, method)(*args, **(keywords[0] if keywords else {}))
    print(writer.rows, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)


if __name__ == "__main__":
    _child()
