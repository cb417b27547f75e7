"""The command line's traps closed (issue 34): the bench is always named, options that take values never swallow a
run file, `--help` shows defaults, progress bars count whole units, `--realtime` reaches the simulated bench."""

from __future__ import annotations

import io
import time

import pytest

from benchlab.cli import build_parser, main
from benchlab.progress import TerminalProgress
from benchlab.runner.session import RunRequest, execute
from protocols.schedule import Step
from sim_bench.bench import SimulatedBench


def test_run_without_bench_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "x.h5"
    assert main(["run", "table1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--bench" in err and "'sim'" in err and "BENCH.toml" in err
    assert not out.exists()
    assert main(["run", "table1", "--dry-run"]) == 2  # a plan is for a bench too


@pytest.mark.parametrize("argv, flag", [(["identify", "--validate", "V.h5", "--validate", "V2.h5", "RUN.h5",
                                          "--out", "P.json"], "validate"),
                                         (["identify", "--fix", "C_T=13000", "--fix", "R0=0.1,a1=0.3", "RUN.h5",
                                           "--out", "P.json"], "fix"),
                                         (["report", "--validate", "V.h5", "RUN.h5", "--params", "P.json",
                                           "--out", "D"], "validate"),
                                         (["import", "--unit", "a=A", "--unit", "b=rpm,c=degC", "DATA.csv",
                                           "--out", "R.h5"], "unit")])
def test_repeatable_options_leave_the_run_file_to_the_positional(argv, flag, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = build_parser().parse_args(argv)
    values = getattr(args, flag)
    positional = getattr(args, "runs", None) or getattr(args, "inputs", None) or [args.run]
    assert positional == [next(a for a in argv if a in ("RUN.h5", "DATA.csv"))]
    expected = {"validate": ["V.h5", "V2.h5"] if "V2.h5" in argv else ["V.h5"],
                "fix": ["C_T=13000", "R0=0.1", "a1=0.3"], "unit": ["a=A", "b=rpm", "c=degC"]}[flag]
    assert values == expected


def test_help_shows_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: 6)" in text  # --starts
    assert "(default: 0)" in text  # --seed: a default of 0 is still a default
    assert "(default: None)" not in text and "(default: False)" not in text


def test_progress_counts_whole_units(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr("sys.stderr", stream)
    task = TerminalProgress().task("table1 on the simulated bench", 3840.0, unit="s")
    for _ in range(20621):
        task.advance(0.05)  # the runner's fast ticks: 1031.05 s
    task.close()
    last = stream.getvalue().replace("\r", "\n").strip().splitlines()[-1]
    assert "1031/3840" in last and "1031.0" not in last and "3840.0" not in last


def test_realtime_paces_the_simulated_bench(tmp_path):
    """A 10 s run at 5x real time takes at least 1.5 s (loosely: 2 s nominal; a loaded machine only makes it slower)."""
    steps = (Step("open", 10.0, 1000.0, 0.0, 0.0, 0),)
    start = time.monotonic()
    code, summary = execute(RunRequest("custom", tmp_path / "r.h5", steps=steps, install_signals=False,
                                       bench=SimulatedBench(realtime=5.0, options={"dropouts": False})))
    wall = time.monotonic() - start
    assert code == 0 and summary.sim_s >= 10.0
    assert wall >= 1.5 and summary.sim_s / summary.wall_s <= 10.0 / 1.5


def test_the_command_line_asks_for_realtime_where_it_makes_sense(tmp_path, monkeypatch, capsys):
    import benchlab.runner.session as session

    asked = []
    monkeypatch.setattr(session, "execute", lambda request: (asked.append(request.bench), (0, None))[1])
    assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(tmp_path / "a.h5"),
                 "--realtime", "20"]) == 0
    assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(tmp_path / "b.h5"),
                 "--realtime"]) == 0
    assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(tmp_path / "c.h5")]) == 0
    assert [getattr(b, "realtime", None) for b in asked] == [20.0, 1.0, None]
    capsys.readouterr()
    assert main(["run", "table1", "--bench", "examples/bench.toml", "--realtime", "2", "--out",
                 str(tmp_path / "d.h5")]) == 2
    assert "--realtime" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:
        main(["run", "--realtime", "table1", "--bench", "sim", "--out", str(tmp_path / "e.h5")])
    assert usage.value.code == 2 and "give PROTOCOL before --realtime" in capsys.readouterr().err
