"""Ctrl-C at the awkward moments of `python -m benchlab.cli`: always exit 130 and one line, never a traceback.

Each case runs the real command line in a subprocess (the exit status is the interpreter's, not main's) through
a small `-m` module that sends SIGINT at the chosen moment; nothing depends on timing.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import benchlab

WAIT_S = 120.0  # upper bound on a subprocess; never reached on a working machine

#: The first Ctrl-C lands in the command's own code, or while source text runs under exec(): as it does when it
#: comes while a dataclass, a namedtuple or a numba function is being made (seen in `benchlab run`: a dataclass
#: of python-can made while the simulated bench was imported), which CPython notes as an unhandled interrupt.
_CASE = '''
import functools, os, signal, sys
import benchlab.cli as cli
from benchlab.interrupts import RedeliverInterrupts

class DropRaisesCtrlC:
    def __del__(self):
        raise KeyboardInterrupt

def configure_logging(verbosity):
    {before}
    {first}

class SecondCtrlCAfterTheLine:
    def __init__(self, stream):
        self.stream, self.sent = stream, False
    def write(self, text):
        written = self.stream.write(text)
        if "\\n" in text and not self.sent and {while_printing}:
            self.sent = True
            signal.raise_signal(signal.SIGINT)
        return written
    def flush(self):
        self.stream.flush()

cli.configure_logging = configure_logging
cli.RedeliverInterrupts = functools.partial(RedeliverInterrupts, delay_s=60.0)  # pending until main ends
sys.stderr = SecondCtrlCAfterTheLine(sys.stderr)
code = cli.main(sys.argv[1:])
if {after_main}:
    signal.raise_signal(signal.SIGINT)
sys.exit(code)
'''

_IN_SOURCE_TEXT = 'exec("signal.raise_signal(signal.SIGINT)", {"signal": signal})'
_IN_CODE = "signal.raise_signal(signal.SIGINT)"
_MOMENTS = {
    "inside exec'd source text": {"first": _IN_SOURCE_TEXT, "before": "pass", "while_printing": False,
                                  "after_main": False},
    "again while the line is printed": {"first": _IN_CODE, "before": "pass", "while_printing": True,
                                        "after_main": False},
    "again after main returned": {"first": _IN_CODE, "before": "pass", "while_printing": False, "after_main": True},
    "also one swallowed by a finaliser": {"first": _IN_CODE, "before": "DropRaisesCtrlC()", "while_printing": False,
                                          "after_main": False},
}


@pytest.mark.parametrize("moment", list(_MOMENTS))
def test_ctrl_c_at_an_awkward_moment_is_exit_130_and_one_line(tmp_path, moment):
    (tmp_path / "ctrl_c_case.py").write_text(_CASE.format(**_MOMENTS[moment]))
    root = str(Path(benchlab.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), root])}
    proc = subprocess.run([sys.executable, "-m", "ctrl_c_case", "run", "table1", "--bench", "sim", "--dry-run"],
                          cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=WAIT_S)
    assert proc.returncode == 130, proc.stderr  # not -2: Python ending itself by SIGINT after main answered
    assert proc.stderr.splitlines() == ["benchlab run: interrupted"], proc.stderr


#: SIGTERM sent while `benchlab run` starts up: while it plans (before the run's own handlers) and while it opens
#: the bench (the runner does not exist yet).
_SIGTERM_CASE = '''
import signal, sys
import benchlab.cli as cli
import benchlab.runner.session as session

def sending_sigterm(original):
    def wrapped(*args, **kwargs):
        signal.raise_signal(signal.SIGTERM)
        return original(*args, **kwargs)
    return wrapped

session.{target} = sending_sigterm(session.{target})
sys.exit(cli.main(sys.argv[1:]))
'''


@pytest.mark.parametrize("target", ["plan", "open_bench"])
def test_sigterm_during_start_up_ends_the_run_as_ctrl_c_does_with_exit_143(tmp_path, target):
    """Issue 29: SIGTERM during start-up used to kill the process by the signal and leave the run's `.lock`."""
    (tmp_path / "sigterm_case.py").write_text(_SIGTERM_CASE.format(target=target))
    root = str(Path(benchlab.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), root])}
    out = tmp_path / "run.h5"
    proc = subprocess.run([sys.executable, "-m", "sigterm_case", "run", "table1", "--bench", "sim", "--cycles", "1",
                           "--out", str(out), "-q"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=WAIT_S)
    assert proc.returncode == 143, proc.stderr
    assert not list(tmp_path.glob("*.lock")), list(tmp_path.iterdir())
    if out.exists():  # stopped once the run file was made: it says so
        from benchlab.runfile import load_attrs

        assert load_attrs(out)["status"] == "aborted"
    else:
        assert proc.stderr.splitlines() == ["benchlab run: terminated"], proc.stderr


_COMPACTION_CASE = '''
import signal, sys
import benchlab.cli as cli
from benchlab.acquire.writer import RunWriter

close = RunWriter.close

def close_with_a_signal(self, *args, **kwargs):
    signal.raise_signal(signal.{name})
    return close(self, *args, **kwargs)

RunWriter.close = close_with_a_signal
sys.exit(cli.main(sys.argv[1:]))
'''


@pytest.mark.parametrize("name, code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_signal_during_the_final_compaction_ends_the_run_aborted(tmp_path, name, code):
    """Issue 29: SIGINT/SIGTERM while the run file was compacted were swallowed (exit 0, status complete)."""
    (tmp_path / "compaction_case.py").write_text(_COMPACTION_CASE.format(name=name))
    root = str(Path(benchlab.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), root])}
    out = tmp_path / "run.h5"
    proc = subprocess.run([sys.executable, "-m", "compaction_case", "run", "table1", "--bench", "sim", "--duration",
                           "200", "--out", str(out), "-q"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=WAIT_S)
    from benchlab.runfile import load_attrs

    assert proc.returncode == code, proc.stderr
    assert load_attrs(out)["status"] == "aborted" and not list(tmp_path.glob("*.lock"))


_EARLY_CASE = '''
import os, signal, sys
import benchlab.console as console

console.note_interrupts()  # as console.main does first
os.kill(os.getpid(), signal.{signal})  # before benchlab.cli is imported
assert "benchlab.cli" not in sys.modules
sys.exit(console.main())
'''


@pytest.mark.parametrize("name, code, line", [("SIGTERM", 143, "benchlab: terminated"),
                                              ("SIGINT", 130, "benchlab: interrupted")])
def test_an_interrupt_before_the_command_line_has_loaded_is_answered_not_fatal(tmp_path, name, code, line):
    """Issue 44: SIGTERM in the first part of a second (while benchlab.cli and its commands load) killed the
    process by the default handler. The console script notes it from its first line; main answers it."""
    (tmp_path / "early_case.py").write_text(_EARLY_CASE.format(signal=name))
    root = str(Path(benchlab.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), root])}
    proc = subprocess.run([sys.executable, "-m", "early_case", "run", "table1", "--bench", "sim", "--dry-run"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=WAIT_S)
    assert proc.returncode == code, proc.stderr
    assert proc.stderr.splitlines() == [line], proc.stderr
    assert proc.stdout == ""  # nothing ran


def test_the_console_script_is_the_one_that_notes_interrupts_first():
    from importlib.metadata import entry_points

    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "benchlab"]
    assert script.value == "benchlab.console:main"
