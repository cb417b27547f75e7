"""A full disk (issue 30), made with the file-size limit RLIMIT_FSIZE in a child process (mounting a small tmpfs may
not be possible): while running, the run file is `aborted`, readable up to its last flush, and the command says so
in one line naming the file (exit 1); anywhere else one line and no partial output, an earlier file kept."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from benchlab.runfile import load_attrs, load_progress, load_run

#: The child's preamble: SIGXFSZ ignored (a write beyond the limit is then EFBIG, as ENOSPC on a full disk).
LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
def limit(size):
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, resource.RLIM_INFINITY))
"""


def _child(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", LIMITED + textwrap.dedent(code)], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def _one_line(err: str, path: Path) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert str(path) in lines[0] and "no space left" in lines[0], err
    return lines[0]


def test_a_disk_that_fills_during_a_run_leaves_an_aborted_run_readable_to_its_last_flush(tmp_path):
    """The disk fills after the fifth flush (the limit drops below the run file's size): growing or closing the file
    fails. It used to stay `running`, with two lines of HDF5 text."""
    out = tmp_path / "run.h5"
    done = _child(f"""
        from benchlab.acquire import writer
        real = writer.RunWriter.flush
        def flush(self, now=None):
            real(self, now)
            if self.flushes == 5:  # from here on the disk has no room: the limit is below the file's size
                limit(100_000)
        writer.RunWriter.flush = flush
        from benchlab.cli import main
        sys.exit(main(["run", "table1", "--bench", "sim", "--duration", "120", "--out", {str(out)!r}, "--quiet"]))
        """, tmp_path)
    assert done.returncode == 1, done.stderr
    line = _one_line(done.stderr, out)
    assert "status aborted" in line and "last flush" in line
    assert load_attrs(out)["status"] == "aborted"
    progress = load_progress(out)
    rows = int(progress["aligned_rows"])
    run = load_run(out)
    measured = run["T_air"].iloc[:rows].notna()
    assert rows > 0 and measured.mean() > 0.9 and measured.iloc[-100:].all()  # readable, measured to the last flush
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())  # no half-made copy beside it


@pytest.mark.parametrize("argv, out", [
    (["simulate", "RUN", "--params", "P", "--out", "OUT", "--force"], "sim.h5"),
    (["export", "RUN", "--to", "OUT", "--force"], "run.csv"),
    (["identify", "RUN", "--model", "linear", "--starts", "1", "--out", "OUT", "--force"], "fit.json"),
])
def test_a_full_disk_elsewhere_is_one_line_and_the_earlier_file_is_kept(argv, out, run_file, params_file, tmp_path):
    target = tmp_path / out
    target.write_text("an earlier result")
    names = {"RUN": str(run_file), "P": str(params_file), "OUT": str(target)}
    argv = [names.get(a, a) for a in argv]
    done = _child(f"""
        from benchlab.cli import main
        limit(1_000)  # no output of these fits in a kilobyte
        sys.exit(main({argv!r}))
        """, tmp_path)
    assert done.returncode == 1, done.stderr
    _one_line(done.stderr, target)
    assert target.read_text() == "an earlier result"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run.h5", "p.json", out])  # no partial output


def test_a_disk_too_full_for_the_run_file_is_one_line_and_no_file(tmp_path):
    """The run file is allocated for the planned run when it starts: no room, no file (and no CAN log without it)."""
    out = tmp_path / "run.h5"
    done = _child(f"""
        from benchlab.cli import main
        limit(1_000_000)
        sys.exit(main(["run", "table1", "--bench", "sim", "--duration", "1800", "--out", {str(out)!r}, "--quiet"]))
        """, tmp_path)
    assert done.returncode == 1, done.stderr
    _one_line(done.stderr, out)
    assert list(tmp_path.iterdir()) == []


def test_a_compiled_function_whose_cache_cannot_be_written_still_runs(tmp_path):
    """numba writes a function's cache file on its first call and raised that write's OSError into the command
    (identify died on a full disk before its own output, on a cold cache); benchlab.jit logs it instead."""
    (tmp_path / "kernel.py").write_text(textwrap.dedent("""
        from benchlab.jit import njit

        @njit(cache=True)
        def twice(x):
            return 2.0 * x
        """))
    done = _child("""
        sys.path.insert(0, ".")
        import kernel
        limit(1_000)  # no cache file fits
        print(kernel.twice(21.0))
        """, tmp_path)
    assert done.returncode == 0 and done.stdout.strip() == "42.0", done.stderr
    assert not list((tmp_path / "__pycache__").glob("*.nbc"))  # the cache was indeed not written
