"""A run file is never half made and never shared: Ctrl-C at start-up, two runs on one path (issue 12).

Subprocesses run the real command; every wait is bounded and nothing asserts on wall-clock time.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from benchlab.acquire.lock import RunFileLock
from benchlab.cli import main
from benchlab.errors import InputError
from benchlab.interrupts import RedeliverInterrupts, interrupts_held
from benchlab.runfile import load_run

WAIT_S = 120.0  # upper bound on any wait for a subprocess; never reached on a working machine


def _start(out: Path, *extra: str) -> subprocess.Popen:
    """`benchlab run table1 ... --out OUT --quiet` as a subprocess."""
    return subprocess.Popen([sys.executable, "-m", "benchlab.cli", "run", "table1", "--bench", "sim", "--out", str(out),
                             "--quiet", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(condition, proc: subprocess.Popen) -> None:
    """Poll `condition` until it holds or the process ends (bounded by WAIT_S)."""
    deadline = time.monotonic() + WAIT_S
    while not condition() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.001)


def _seed(path: Path) -> int:
    with h5py.File(path, "r") as f:
        return int(f.attrs["seed"])


@pytest.mark.parametrize("moment", ["0.3 s", "1.5 s", "file being built", "file just created"])
def test_ctrl_c_during_start_up_is_exit_130_without_a_half_made_file(tmp_path, moment):
    out = tmp_path / "run.h5"
    tmp = out.with_name(out.name + ".tmp")
    proc = _start(out, "--duration", "3600")  # long: the run itself cannot end before the signal
    if moment.endswith(" s"):
        time.sleep(float(moment.split()[0]))
    elif moment == "file being built":
        _wait_for(lambda: tmp.exists() or out.exists(), proc)
    else:
        _wait_for(out.exists, proc)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "Exception ignored" not in stderr and len(stderr.splitlines()) <= 1, stderr
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left in ([], ["run.blf", "run.h5"]), left  # no .tmp, no .lock, no CAN log without its run file
    if left:
        assert load_run(out).attrs["status"] in ("running", "aborted")  # readable: resumable or closed


def test_ctrl_c_held_during_imports_arrives_when_they_end():
    """A Ctrl-C inside an extension module's initialisation would surface as its ImportError (numpy's, seen in CI:
    exit 1 instead of 130); the CLI holds it back while it imports the commands, and it arrives right after."""
    reached_end_of_block = False
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # a delivered signal would have raised by now
            reached_end_of_block = True
    assert reached_end_of_block


def test_two_runs_on_one_file_one_is_refused_and_the_other_keeps_its_data(tmp_path):
    out = tmp_path / "same.h5"
    first, second = _start(out, "--cycles", "1", "--seed", "1"), _start(out, "--cycles", "1", "--seed", "2")
    results = {1: first.communicate(timeout=WAIT_S), 2: second.communicate(timeout=WAIT_S)}
    codes = {1: first.returncode, 2: second.returncode}
    assert sorted(codes.values()) == [0, 2], results
    winner = next(seed for seed, code in codes.items() if code == 0)
    loser = 3 - winner
    assert "run complete" in results[winner][0] and "run complete" not in results[loser][0]
    err = results[loser][1].strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and str(out) in err[0] and "Traceback" not in results[loser][1]
    assert _seed(out) == winner and load_run(out).attrs["status"] == "complete"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.blf", "same.h5"]  # the winner's run and CAN log


def test_a_locked_run_file_is_refused_even_with_force_and_taken_once_free(tmp_path, capsys):
    out = tmp_path / "run.h5"
    with RunFileLock(out):  # as a run in another process would hold it
        assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert f"process {os.getpid()}" in err and "--out" in err and len(err.strip().splitlines()) == 1
        assert not out.exists()
    assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--seed", "1", "--out", str(out), "--quiet"]) == 0
    before = out.read_bytes()
    with RunFileLock(out):
        assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--seed", "2", "--out", str(out),
                     "--force"]) == 2
        assert main(["run", "--resume", str(out), "--bench", "sim"]) == 2
        assert "--resume" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--seed", "2", "--out", str(out), "--force",
                 "--quiet"]) == 0
    assert _seed(out) == 2 and sorted(p.name for p in tmp_path.iterdir()) == ["run.blf", "run.h5"]


def test_a_lock_file_left_by_a_killed_run_is_taken_over(tmp_path):
    out = tmp_path / "run.h5"
    stale = out.with_name("run.h5.lock")
    stale.write_text("999999\n")  # no process holds a lock on it
    with RunFileLock(out) as lock:
        assert stale.read_text().strip() == str(os.getpid())
        with pytest.raises(InputError, match="no other run"):
            RunFileLock(out).acquire()
    assert not stale.exists() and lock.lock_path == stale


def _killed_holder(tmp_path: Path, out: Path) -> None:
    """A process that took the lock of `out` and was killed (SIGKILL) before it made the run file."""
    import signal
    import subprocess
    import sys

    code = (f"import os, signal\nfrom benchlab.acquire.lock import RunFileLock\nRunFileLock({str(out)!r}).acquire()\n"
            "os.kill(os.getpid(), signal.SIGKILL)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, timeout=120)
    assert proc.returncode == -signal.SIGKILL and out.with_name(out.name + ".lock").exists() and not out.exists()


def test_a_lock_left_before_its_run_file_existed_is_removed_by_the_next_run_in_the_directory(tmp_path):
    """Issue 44: a run killed (SIGKILL) before it made its file left RUN.h5.lock for good. The next run in that
    directory removes it; a lock a live run holds, one whose run file exists, and another tool's are kept."""
    _killed_holder(tmp_path, tmp_path / "killed.h5")
    (tmp_path / "resumable.h5").write_bytes(b"")  # its run file is there: the next run on it takes the lock over
    (tmp_path / "resumable.h5.lock").write_text("999999\n")
    (tmp_path / "other.h5.lock").write_text("held by another tool\n")
    with RunFileLock(tmp_path / "live.h5"):
        with RunFileLock(tmp_path / "next.h5"):
            assert sorted(p.name for p in tmp_path.glob("*.lock")) == ["live.h5.lock", "next.h5.lock",
                                                                       "other.h5.lock", "resumable.h5.lock"]
    assert sorted(p.name for p in tmp_path.glob("*.lock")) == ["other.h5.lock", "resumable.h5.lock"]


class _RaisesInFinaliser:
    """An object whose finaliser is hit by Ctrl-C: Python can only report that as unraisable."""

    def __del__(self) -> None:
        raise KeyboardInterrupt


def test_a_ctrl_c_swallowed_by_a_finaliser_is_raised_again():
    with pytest.raises(KeyboardInterrupt):
        with RedeliverInterrupts(delay_s=0.01):
            _RaisesInFinaliser()  # dropped at once: its __del__ raises, Python reports it and carries on
            deadline = time.monotonic() + WAIT_S
            while time.monotonic() < deadline:  # ordinary code, where the interrupt arrives again
                time.sleep(0.001)


def test_a_swallowed_ctrl_c_still_pending_at_the_end_is_reported():
    with RedeliverInterrupts(delay_s=WAIT_S) as guard:
        _RaisesInFinaliser()
    assert guard.swallowed  # main() then exits 130; the pending signal was cancelled, never sent
    with RedeliverInterrupts() as quiet:
        pass
    assert not quiet.swallowed
