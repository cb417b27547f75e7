"""Bad input on the command line and in run or bench files: exit 2, one line naming file or field, no traceback.

Issue 12: numbers a bench cannot do are refused at parse time (they used to hang with growing memory), and
inputs that used to end in exit 1 with a Python error name what was expected instead.
"""

from __future__ import annotations

import pytest

from benchlab.bounds import MAX_CYCLES, MAX_RUN_DURATION_S, MAX_SCAN_CHANNELS, MAX_TIMEOUT_S
from benchlab.cli import main


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Exit code and stderr of `benchlab ARGV` (argparse's usage errors end in SystemExit)."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


def _refused(argv: list[str], field: str, capsys: pytest.CaptureFixture[str]) -> str:
    code, err = _cli(argv, capsys)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and field in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("value", ["inf", "1e12", "-5", "nan", "0", str(MAX_RUN_DURATION_S * 1.001)])
def test_run_duration_out_of_bounds_is_refused_at_parse_time(value, tmp_path, capsys):
    _refused(["run", "table1", "--duration", value, "--out", str(tmp_path / "r.h5")], "--duration", capsys)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("value", ["1000000000", "0", "-1", "1.5", str(MAX_CYCLES + 1)])
def test_run_cycles_out_of_bounds_is_refused(value, tmp_path, capsys):
    _refused(["run", "table1", "--cycles", value, "--out", str(tmp_path / "r.h5")], "--cycles", capsys)


def test_schedule_longer_than_the_longest_run_is_refused_before_anything_moves(tmp_path, capsys):
    err = _refused(["run", "table1", "--cycles", str(MAX_CYCLES), "--out", str(tmp_path / "r.h5")], "schedule",
                   capsys)
    assert "planned duration" in err and not (tmp_path / "r.h5").exists()


def test_probe_channel_list_beyond_the_scanner_is_refused(capsys):
    err = _refused(["probe", "pt1000", "--url", "sim://instrument", "--channels", "(@1:99999999)"], "--channels",
                   capsys)
    assert str(MAX_SCAN_CHANNELS) in err


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "0", "1e12", str(MAX_TIMEOUT_S + 1)])
def test_probe_timeout_out_of_bounds_is_refused(value, capsys):
    _refused(["probe", "node", "--url", "sim://node", "--timeout", value], "--timeout", capsys)


def test_probe_reading_count_is_bounded(capsys):
    _refused(["probe", "node", "--url", "sim://node", "--count", "1000000000"], "--count", capsys)


@pytest.mark.parametrize("argv,field", [
    (["run", "table1", "--seed", "-1"], "--seed"),
    (["identify", "RUN", "--starts", "0", "--out", "p.json"], "--starts"),
    (["identify", "RUN", "--seed", "-3", "--out", "p.json"], "--seed"),
])
def test_counts_and_seeds_are_checked(argv, field, tmp_path, capsys):
    argv = [str(tmp_path / "run.h5") if a == "RUN" else a for a in argv]
    _refused(argv + (["--out", str(tmp_path / "r.h5")] if argv[0] == "run" else []), field, capsys)
