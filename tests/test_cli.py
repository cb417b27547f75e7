"""The `benchlab` command itself: --version, -v logging on stderr, a reader that leaves the pipe early."""

from __future__ import annotations

import subprocess
import sys

import pytest

import benchlab
from benchlab import cli


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"benchlab {benchlab.__version__}"


def test_verbose_logs_benchlab_messages_on_stderr(run_file, tmp_path, capsys):
    assert cli.main(["export", str(run_file), "--to", str(tmp_path / "a.csv")]) == 0
    assert capsys.readouterr().err == ""  # nothing logged without -v
    assert cli.main(["-v", "export", str(run_file), "--to", str(tmp_path / "b.csv")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert "INFO benchlab.export: " in err[0] and "/aligned" in err[0] and any("wrote" in line for line in err)
    assert cli.main(["export", str(run_file), "--to", str(tmp_path / "c.csv")]) == 0
    assert capsys.readouterr().err == ""  # the level goes back with the flag


def test_a_reader_that_leaves_early_ends_the_command_quietly():
    proc = subprocess.Popen([sys.executable, "-m", "benchlab.cli", "run", "table1", "--bench", "sim", "--dry-run"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # `| head -1` gone before the schedule is printed
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == cli.BROKEN_PIPE_EXIT and err == ""


def test_a_broken_pipe_elsewhere_is_still_a_failure(monkeypatch, capsys):
    def handler(args):
        raise BrokenPipeError(32, "Broken pipe")  # a socket's, say: stdout is fine

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda command=None: parser)
    monkeypatch.setattr(parser, "parse_args", lambda argv: cli.argparse.Namespace(
        command="probe", handler=handler, debug=False, verbose=0))
    assert cli.main(["probe"]) == 1
    assert "failed: BrokenPipeError" in capsys.readouterr().err
