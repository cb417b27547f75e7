"""A 2-hour Table 1 run on the simulated bench: killed with SIGKILL in the middle, readable, resumed to the end.

The run file and the raw CAN log beside it both survive the kill: the log reads back with python-can up to
about the last second of the run file's data, /truth up to the true states that were final and written (at most
the three chunks the bench keeps, 30 s, and a batch of rows, 82 s, behind), NaN after. (How fast the bench runs is benchmarks/bench_sim_bench.py's job.)
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import can
import h5py
import numpy as np

from benchlab.acquire.writer import TRUTH_BATCH_ROWS
from benchlab.runfile import load_run, load_truth, read_progress
from benchlab.runner.session import can_log_path


def _progress(path):
    try:
        with h5py.File(path, "r") as f:
            return read_progress(f)
    except (OSError, KeyError):
        return None


def test_two_hour_table1_killed_readable_and_resumed(tmp_path):
    out = tmp_path / "table1.h5"
    cmd = [sys.executable, "-m", "benchlab.cli", "run", "table1", "--bench", "sim", "--seed", "3",
           "--duration", "7200", "--out", str(out), "--quiet"]
    wall0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    progress = None
    while time.perf_counter() - wall0 < 600:
        progress = _progress(out) if out.exists() else None
        if progress and progress["t_data"] > 2400:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()

    run = load_run(out)  # readable as it was left
    assert run.attrs["status"] == "running"
    progress = _progress(out)
    rows = int(progress["aligned_rows"])
    assert progress["t_data"] > 2400 and rows > 240000
    assert np.isfinite(run["engine_speed"].to_numpy()[rows - 200:rows]).all()  # data up to the last flush
    cycle_at_kill = int(progress["state/cycle"])
    before = {c: run[c].to_numpy()[:rows] for c in ("T_flywheel", "engine_speed", "friction_power")}
    stamps = [m.timestamp for m in can.LogReader(str(can_log_path(out)))]  # the killed run's CAN log
    assert len(stamps) > 300 * 2400 and progress["t_data"] - 2.0 < stamps[-1] <= progress["t_data"] + 2.0
    truth = load_truth(out)  # written as the run went: the final rows, then NaN up to the progress record
    flywheel = truth["T_flywheel"].to_numpy()
    final = int(np.argmax(np.isnan(flywheel)))
    assert len(truth) == rows and rows - 3100 - TRUTH_BATCH_ROWS <= final < rows and np.isnan(flywheel[final:]).all()
    sensor = run["T_flywheel_1"].to_numpy()[:final] - truth["T_flywheel_1"].to_numpy()[:final]
    assert np.sqrt(np.nanmean(sensor ** 2)) < 0.1  # the node's sensor reads it within its noise (docs/plant.md)

    done = subprocess.run([sys.executable, "-m", "benchlab.cli", "run", "--resume", str(out), "--bench", "sim",
                           "--quiet"], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert can_log_path(out, 1).exists()
    run = load_run(out)
    assert run.attrs["status"] == "complete"
    assert run["time"].iloc[-1] > 6000
    for c, values in before.items():  # what was acquired before the kill is kept as it was
        np.testing.assert_array_equal(run[c].to_numpy()[:rows], values)
    resumed = load_truth(out)  # the killed run's final rows kept, NaN where it had none, the resumed bench's after
    np.testing.assert_array_equal(resumed["T_flywheel"].to_numpy()[:rows], flywheel)
    assert len(resumed) == len(run) and np.isfinite(resumed.to_numpy()[rows:]).all()
    with h5py.File(out, "r") as f:
        kinds = [k.decode() for k in f["events/kind"][:]]
        cycles = f["events/cycle"][:]
        starts = sorted(set(cycles[np.array(kinds) == "cycle_start"].tolist()))
    assert "resume" in kinds
    assert cycle_at_kill + 1 in starts and starts[-1] == max(starts)  # went on with the next planned cycle
