"""The one output rule (benchlab.outputs, issue 30): no command replaces or modifies a run file it reads, `--force`
replaces only a regular file, and every output is renamed into place when whole. A test per command tries it."""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import h5py
import pytest

from benchlab.cli import main
from benchlab.errors import InputError
from benchlab.outputs import check_output, replacing, write_text
from benchlab.runfile import load_attrs, load_run


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()



#: Each command with the option that names its output; RUN is the run file it reads, P the parameter file, OUT the
#: output under test.
COMMANDS = {
    "identify": ["identify", "RUN", "--model", "linear", "--starts", "1", "--out", "OUT"],
    "simulate": ["simulate", "RUN", "--params", "P", "--out", "OUT"],
    "observe": ["observe", "RUN", "--params", "P", "--out", "OUT"],
    "observe --plot": ["observe", "RUN", "--params", "P", "--out", "EST", "--plot", "OUT"],
    "wear --plot": ["wear", "RUN", "--params", "P", "--plot", "OUT"],
    "diagnose --save-model": ["diagnose", "RUN", "--save-model", "OUT"],
    "export": ["export", "RUN", "--to", "OUT"],
    "cooldown --out": ["cooldown", "RUN", "--params", "P", "--out", "OUT"],
}


def _argv(command: str, run: Path, params: Path, out: Path, tmp_path: Path) -> list[str]:
    names = {"RUN": str(run), "P": str(params), "OUT": str(out), "EST": str(tmp_path / "est.h5")}
    return [names.get(a, a) for a in COMMANDS[command]]


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_no_command_writes_over_the_run_file_it_reads(command, force, foreign_run, params_file, tmp_path,
                                                      refused):
    """`identify c.h5 --out c.h5` used to turn the measurement into JSON; by any name, with --force, it is refused."""
    run = foreign_run
    if command == "export":  # export wants a known suffix: the same run file under a .csv name (a hard link)
        os.link(foreign_run, tmp_path / "run.csv")
        run = tmp_path / "run.csv"
    before = _digest(run)
    argv = _argv(command, run, params_file, run, tmp_path) + (["--force"] if force else [])
    refused(argv, str(run))
    assert _digest(run) == before
    alias = tmp_path / ("alias.csv" if command == "export" else "alias.h5")
    os.link(run, alias)  # another name for the same file
    argv = _argv(command, run, params_file, alias, tmp_path) + ["--force"]
    refused(argv, "other input it reads")
    assert _digest(run) == before and not (tmp_path / "est.h5").exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_no_command_but_a_run_writer_replaces_another_run_file(command, foreign_run, run_file, params_file, tmp_path,
                                                                refused):
    """A run file that is not an input is a measurement too: only run, import, simulate and observe (whose outputs
    are run files) may replace one (--force)."""
    target = tmp_path / ("other.csv" if command == "export" else "other.h5")
    target.write_bytes(run_file.read_bytes())
    before = _digest(target)
    argv = _argv(command, foreign_run, params_file, target, tmp_path) + ["--force"]
    if command in ("simulate", "observe"):  # their outputs are run files: replaced on --force (refused without it)
        assert main(argv) == 0
        assert load_attrs(target)["source_run"] == str(foreign_run)
        return
    refused(argv, "run file")
    assert _digest(target) == before


@pytest.mark.parametrize("kind", ["directory", "fifo", "symlink"])
@pytest.mark.parametrize("command", sorted(COMMANDS) + ["run", "import"])
def test_force_never_replaces_what_is_not_a_regular_file(command, kind, foreign_run, params_file, tmp_path,
                                                         refused):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "precious.txt").write_text("keep me")
    out = tmp_path / ("target.csv" if command == "export" else "target.h5")
    if kind == "directory":
        out.mkdir()
    elif kind == "fifo":
        os.mkfifo(out)
    else:
        out.symlink_to(outside / "precious.txt")
    if command == "run":
        argv = ["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(out)]
    elif command == "import":
        (tmp_path / "d.csv").write_text("time,engine_speed\n0,1\n")
        argv = ["import", str(tmp_path / "d.csv"), "--out", str(out)]
    else:
        argv = _argv(command, foreign_run, params_file, out, tmp_path)
    refused(argv + ["--force"], str(out), {"directory": "a directory", "fifo": "a FIFO",
                                                     "symlink": "a symbolic link"}[kind])
    assert (outside / "precious.txt").read_text() == "keep me"
    assert {"directory": out.is_dir, "fifo": out.is_fifo, "symlink": out.is_symlink}[kind]()


@pytest.mark.parametrize("command", ["run", "import", "simulate", "identify", "export", "observe", "wear --plot",
                                     "diagnose --save-model", "cooldown --out"])
def test_an_existing_output_is_refused_without_force(command, foreign_run, params_file, tmp_path, refused):
    out = tmp_path / ("old.csv" if command == "export" else "old.out")
    out.write_text("an earlier result")
    if command == "run":
        argv = ["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(out)]
    elif command == "import":
        argv = ["import", str(tmp_path / "d.csv"), "--out", str(out)]
    else:
        argv = _argv(command, foreign_run, params_file, out, tmp_path)
    refused(argv, str(out), "--force")
    assert out.read_text() == "an earlier result"


@pytest.mark.parametrize("command", ["identify", "simulate", "export"])
def test_force_replaces_a_regular_file_whole(command, foreign_run, params_file, tmp_path):
    out = tmp_path / ("old.csv" if command == "export" else "old.out")
    out.write_text("an earlier result")
    assert main(_argv(command, foreign_run, params_file, out, tmp_path) + ["--force"]) == 0
    assert out.read_bytes() != b"an earlier result"
    assert [p.name for p in tmp_path.iterdir() if ".part" in p.name] == []  # no temporary file left beside it


@pytest.mark.parametrize("argv", [["run", "--bench", "sim", "--out", "R", "--cycles", "1", "table1"],
                                  ["import", "CSV", "--out", "R"]])
def test_run_writers_replace_a_run_file_only_with_force(argv, foreign_run, run_file, tmp_path, refused):
    (tmp_path / "d.csv").write_text(load_run(run_file).iloc[:100].to_csv(index=False))
    names = {"R": str(foreign_run), "CSV": str(tmp_path / "d.csv")}
    argv = [names.get(a, a) for a in argv]
    before = _digest(foreign_run)
    refused(argv, "--force")
    assert _digest(foreign_run) == before
    if argv[0] == "import":
        assert main(argv + ["--force"]) == 0 and len(load_run(foreign_run)) == 100


def test_cooldown_leaves_the_run_file_alone_unless_asked(foreign_run, params_file, tmp_path, refused):
    """`cooldown RUN.h5` used to write /analysis into the run by default; now only --store does (or --out elsewhere).
    The foreign run has no cool-downs: refused as such, and the file is untouched either way."""
    before = _digest(foreign_run)
    refused(["cooldown", str(foreign_run), "--params", str(params_file)], "a cool-down sweep run")
    assert _digest(foreign_run) == before
    refused(["cooldown", str(foreign_run), "--params", str(params_file), "--store", "--out", str(tmp_path / "a.h5")],
            "--store")


@pytest.mark.parametrize("argv, option", [
    (["report", "RUN", "--params", "P", "--out", "DIR"], "--out"),
    (["diagnose", "RUN", "--report", "DIR"], "--report"),
    (["pipeline", "--out", "DIR"], "--out"),
    (["batch", "identify", "RUN", "--out", "DIR"], "--out"),
])
def test_an_output_directory_holding_files_needs_force_and_a_run_file_is_not_one(argv, option, foreign_run,
                                                                                 params_file, tmp_path, refused):
    folder = tmp_path / "earlier"
    folder.mkdir()
    (folder / "report.md").write_text("an earlier page")
    names = {"RUN": str(foreign_run), "P": str(params_file)}
    refused([names.get(a, str(folder) if a == "DIR" else a) for a in argv], str(folder), option, "--force")
    assert (folder / "report.md").read_text() == "an earlier page"
    refused([names.get(a, str(foreign_run) if a == "DIR" else a) for a in argv], option, "a directory")
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link").symlink_to(folder)  # a directory elsewhere, behind a link
    for other, kind in (("fifo", "a FIFO"), ("link", "a symbolic link")):
        refused([names.get(a, str(tmp_path / other) if a == "DIR" else a) for a in argv] + ["--force"], option, kind)
    assert sorted(p.name for p in folder.iterdir()) == ["report.md"]


def test_replacing_refuses_a_run_file_and_leaves_nothing_on_failure(foreign_run, tmp_path):
    """Inside an output directory (--force), a figure never replaces a run file; a failed write leaves the old file."""
    with pytest.raises(InputError, match="run file"):
        with replacing(foreign_run):
            pytest.fail("a run file was about to be replaced")
    old = write_text(tmp_path / "page.md", "old")
    with pytest.raises(RuntimeError):
        with replacing(old) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash while writing")
    assert old.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["f.h5", "page.md"]


@pytest.mark.parametrize("path", ["/dev/null", "/dev/zero"])
def test_a_device_is_never_an_output_even_with_force(path):
    """As root, `run --out /dev/null --force` used to replace /dev/null with a regular file."""
    with pytest.raises(InputError, match="character device"):
        check_output(path, "--out", force=True, run_file=True)


def test_simulate_output_is_a_run_file_and_the_input_keeps_its_bytes(foreign_run, params_file, tmp_path):
    before = _digest(foreign_run)
    assert main(["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")]) == 0
    with h5py.File(tmp_path / "s.h5") as f:
        assert "simulated" in f and f.attrs["schema"] == "benchlab-run/1"
    assert _digest(foreign_run) == before


@pytest.mark.parametrize("kind", ["the input", "another run file", "the --to file", "a FIFO", "a symbolic link",
                                  "a character device", "an existing log"])
def test_log_follows_the_output_rule(kind, foreign_run, run_file, tmp_path, refused):
    """`--log FILE` used to append to anything: the command's own input, a run file, a link's target, a device, and
    blocked forever on a FIFO; now it is an output like any other."""
    out, log = tmp_path / "out.csv", tmp_path / "x.log"
    outside = tmp_path / "precious.txt"
    outside.write_text("keep me")
    other = tmp_path / "other.h5"
    other.write_bytes(run_file.read_bytes())
    if kind == "a FIFO":
        os.mkfifo(log)
    elif kind == "a symbolic link":
        log.symlink_to(outside)
    elif kind == "an existing log":
        log.write_text("an earlier log\n")
    log = {"the input": foreign_run, "another run file": other, "the --to file": out,
           "a character device": Path(os.devnull)}.get(kind, log)
    digests = {p: _digest(p) for p in (foreign_run, other, outside)}
    force = [] if kind == "an existing log" else ["--force"]
    words = {"the input": "command's run", "another run file": "run file", "the --to file": "--to", "a FIFO": "a FIFO",
             "a symbolic link": "a symbolic link", "a character device": "a character device",
             "an existing log": "--force"}[kind]
    line = refused(["export", str(foreign_run), "--to", str(out), "--log", str(log), *force], "--log", str(log))
    assert words in line, line
    assert {p: _digest(p) for p in digests} == digests and not out.exists()
    if kind == "an existing log":  # with --force it is replaced, as any output
        assert main(["export", str(foreign_run), "--to", str(out), "--log", str(log), "--force"]) == 0
        assert "an earlier log" not in log.read_text() and "benchlab.export" in log.read_text()


def test_a_resumed_runs_log_goes_on_and_a_new_one_needs_force(tmp_path):
    from benchlab import logs
    from benchlab.outputs import check_log

    log = tmp_path / "run.log"
    log.write_text("the first part\n")
    with pytest.raises(InputError, match="--force"):
        check_log(log, {"--out": str(tmp_path / "run.h5")}, force=False, resume=False)
    assert check_log(log, {"--resume": str(tmp_path / "run.h5")}, force=False, resume=True) == log
    handler = logs.keep_in_file(log, append=True)
    try:
        logging.getLogger("benchlab.test").warning("the second part")
    finally:
        logs.stop_file(log)
    assert handler.stream.closed
    assert log.read_text().startswith("the first part\n") and "the second part" in log.read_text()


def test_a_partial_file_of_a_killed_writer_is_removed_by_the_next_write(tmp_path):
    """Issue 44: `import` or `export` killed mid-write left a hidden `.NAME.PID-TOKEN.part.EXT` for good. The next
    write of that destination removes those of writers that no longer exist; a live writer's stays."""
    import signal
    import subprocess
    import sys

    out = tmp_path / "table.csv"
    code = (f"import os, signal\nfrom benchlab.outputs import replacing\nwith replacing({str(out)!r}) as tmp:\n"
            "    tmp.write_text('half')\n    os.kill(os.getpid(), signal.SIGKILL)\n")
    proc = subprocess.run([sys.executable, "-c", code], timeout=120)
    assert proc.returncode == -signal.SIGKILL
    (left,) = tmp_path.glob(".table.*.part.csv")
    live = tmp_path / f".table.{os.getpid()}-0123abcd.part.csv"  # this process: a writer still at work
    live.write_text("being written")
    other = tmp_path / ".table.notes.part.csv"  # not a name replacing makes
    other.write_text("")
    write_text(out, "whole")
    assert out.read_text() == "whole" and not left.exists() and live.exists() and other.exists()
