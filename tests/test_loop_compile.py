"""No numba compile inside the real-time control loop: every kernel the bench loop calls is compiled, or loaded
from numba's cache, when the bench is assembled (DriverBench and the run writer's layout), and every kernel of the
simulated bench (emulators, physics, the plant's solver) when it is built, never at a first call after the loop has
commanded the bench (a compile there stops polling and interlocks, or silences the emulated devices, for seconds)."""

import json
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent

# A fresh process (numba's cache warm or cold alike): every new signature numba takes on (compiled or loaded from
# its cache) is noted with the phase it came in.
_PROBE = r"""
import json, sys, tempfile
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from numba.core.dispatcher import Dispatcher

phase, seen = ["open"], []
compile_once = Dispatcher.compile

def noting_compile(self, sig):
    before = len(self.overloads)
    entry = compile_once(self, sig)
    if len(self.overloads) > before:
        seen.append([phase[0], f"{self.py_func.__module__}.{self.py_func.__qualname__}", str(sig)])
    return entry

Dispatcher.compile = noting_compile
from benchlab.runner.clock import RealClock
from benchlab.runner.engine import Runner
from test_runner import _launch_and_open

run_once = Runner.run

def loop_run(self, *args, **kwargs):
    phase[0] = "loop"  # bench and writer are assembled: from here on the loop commands the bench
    return run_once(self, *args, **kwargs)

Runner.run = loop_run
_launch_and_open(Path(tempfile.mkdtemp()) / "rt.h5", RealClock())
print(json.dumps(seen))
"""


def test_the_real_time_loop_compiles_nothing():
    """A real-time run on the emulated devices from a fresh process: the drivers', devices' and writer's kernels and
    the simulated bench's (emulators, physics, solver) all take their signatures before the loop starts, nothing
    takes one inside it, and each kernel takes one signature."""
    out = subprocess.run([sys.executable, "-c", _PROBE, str(TESTS)], capture_output=True, text=True, timeout=900,
                         cwd=TESTS.parent)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    in_loop = [(name, sig) for phase, name, sig in seen if phase == "loop"]
    assert not in_loop, f"compiled inside the control loop: {in_loop}"
    primed = {name for phase, name, _ in seen}
    for kernel in ("drivers.can_bench._classify_decode", "drivers.can_bench._watch", "drivers.can_bench._next_frames",
                   "drivers.clutch_node._read_plain", "benchlab.runner.devices._take_status_frames",
                   "benchlab.runner.devices._derived", "benchlab.acquire.writer._hold_streams",
                   "benchlab.acquire.writer._scatter_streams", "drivers.can_log._fill_can_objects",
                   "sim_bench.emulators.can_controllers._take_commands", "sim_bench.emulators.can_controllers._due_frames",
                   "sim_bench.emulators.can_controllers._frames", "sim_bench.emulators.clutch_node._frame_wire",
                   "sim_bench.emulators.sim_can_bus._any_unstamped", "sim_bench.bench._grid_rows",
                   "sim_bench.bench._measured_at", "sim_bench.drivetrain._fill_piece", "benchlab.network.solver._zoh_kernel",
                   "benchlab.network.solver._propagate"):  # the reference plant's 13 states (the paper's 4: _propagate4)
        assert kernel in primed, f"{kernel} not primed before the loop"
    # one signature per kernel, the drivers' and the writer's too: a second one is a second compile in a first run
    # (a kernel called with the literal 0 besides an int64, or with two array types)
    kernels = [name for _, name, _ in seen if not name.startswith("numba.")]
    twice = sorted({name for name in kernels if kernels.count(name) > 1})
    assert not twice, f"kernels that took two signatures: {[(n, s) for _, n, s in seen if n in twice]}"
