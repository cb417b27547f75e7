"""A stranger's first day at the command line (issue 46): `--channels` takes one value, `-q` works before the
command as `-v` does, a typo gets a suggestion, and the help texts say what the commands write and where the
contract they cite is."""

from __future__ import annotations

import re

import pytest

from benchlab.cli import build_parser, main

COMMANDS = sorted(build_parser()._subparsers._group_actions[0].choices)


def _help(capsys, *argv: str) -> str:
    """`benchlab … --help` as one line of words."""
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_export_channels_take_one_value_and_leave_the_run_file_to_the_positional():
    args = build_parser().parse_args(["export", "--channels", "T_air,engine_speed", "RUN.h5", "--to", "o.csv",
                                      "--channels", "can_drive.speed"])
    assert args.run == "RUN.h5"
    assert args.channels == ["T_air", "engine_speed", "can_drive.speed"]
    assert build_parser().parse_args(["export", "RUN.h5", "--to", "o.csv"]).channels is None


@pytest.mark.parametrize("argv", [["simulate", "RUN.h5", "--params", "p.json", "--out", "o.h5", "-q"],
                                  ["-v", "export", "RUN.h5", "--to", "o.csv", "--channels", "T_air"]])
def test_a_command_lines_own_parser_holds_its_command_only_and_parses_as_the_whole_one(argv):
    """Issue 47: `benchlab CMD` builds CMD's parser alone (every command's imports cost each command 60 ms CPU)."""
    command = argv[1] if argv[0] == "-v" else argv[0]
    own = build_parser(command)
    assert list(own._subparsers._group_actions[0].choices) == [command]
    assert vars(own.parse_args(argv)) == vars(build_parser().parse_args(argv))


@pytest.mark.parametrize("command", ["import", "simulte", None])
def test_a_parser_for_no_command_of_that_module_holds_every_command(command):
    assert sorted(build_parser(command)._subparsers._group_actions[0].choices) == COMMANDS


@pytest.mark.parametrize("argv, quiet", [(["-q", "run", "table1"], True), (["--quiet", "run", "table1"], True),
                                         (["run", "table1", "-q"], True), (["run", "table1"], False),
                                         (["-v", "run", "table1", "-q"], True)])
def test_quiet_is_taken_before_or_after_the_command(argv, quiet):
    args = build_parser().parse_args([*argv, "--bench", "sim", "--dry-run"])
    assert args.quiet is quiet and args.command == "run"


def test_quiet_before_the_command_runs_it(capsys):
    assert main(["-q", "run", "table1", "--bench", "sim", "--dry-run", "--cycles", "1"]) == 0
    assert "launch" in capsys.readouterr().out


@pytest.mark.parametrize("argv, suggestion", [(["identfy"], "identify"), (["dignose"], "diagnose"),
                                              (["run", "table1", "--bench", "sim", "--plant", "refrence"],
                                               "reference")])
def test_a_typo_gets_the_closest_choice(argv, suggestion, capsys):
    with pytest.raises(SystemExit) as ended:  # argparse's usage error: the console script's exit code
        main(argv)
    assert ended.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"did you mean '{suggestion}'?" in err and "choose from" in err


def test_a_word_near_no_choice_gets_no_suggestion(capsys):
    with pytest.raises(SystemExit) as ended:
        main(["frobnicate"])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'frobnicate'" in err and "did you mean" not in err


def test_help_texts_name_the_pages_and_inputs_the_commands_take(capsys):
    report = _help(capsys, "report")
    assert "report.md" in report and "report.html" in report
    diagnose = _help(capsys, "diagnose")
    assert "diagnose.md" in diagnose and "diagnose.html" in diagnose
    imported = _help(capsys, "import")
    assert "CAN log" in imported.split("positional arguments")[0]  # in the description, not only DATA's help
    assert "{,,;,tab}" not in imported and "{',',';',tab}" in imported


@pytest.mark.parametrize("command", COMMANDS)
def test_help_cites_the_contract_by_its_file_and_nothing_outside(command, capsys):
    text = _help(capsys, command)
    assert "../" not in text
    assert not re.search(r"contract(?:'s)? (?:section|§)|(?<!contract\.md )§ ?\d", text), text


def test_log_never_appends_to_a_run_file_or_another_file_of_the_command_line(foreign_run, tmp_path, capsys):
    before = foreign_run.read_bytes()
    params = tmp_path / "p.json"  # `--log` takes the word after it: here the run file meant as identify's input
    assert main(["identify", "--log", str(foreign_run), str(foreign_run), "--out", str(params)]) == 2
    err = capsys.readouterr().err
    assert "--log" in err and "a file of its own" in err and len(err.strip().splitlines()) == 1
    assert foreign_run.read_bytes() == before and not params.exists()
    other = tmp_path / "other.h5"  # a run file named as the log and nowhere else on the command line
    other.write_bytes(before)
    assert main(["identify", str(foreign_run), "--log", str(other), "--out", str(params)]) == 2
    err = capsys.readouterr().err
    assert "--log" in err and "run file" in err and other.read_bytes() == before
    mapping = tmp_path / "map.toml"
    mapping.write_text("")
    assert main(["import", str(tmp_path / "d.csv"), "--mapping", str(mapping), "--log", str(mapping),
                 "--out", str(tmp_path / "r.h5")]) == 2
    assert "--log" in capsys.readouterr().err and mapping.read_text() == ""


def test_an_output_naming_a_run_file_says_so_in_plain_words(foreign_run, tmp_path, capsys):
    other = tmp_path / "other.h5"
    other.write_bytes(foreign_run.read_bytes())
    assert main(["identify", str(foreign_run), "--out", str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--out: a file of another name: this one is a run file, a measurement never written over")
    assert other.read_bytes() == foreign_run.read_bytes()


def test_cooldown_of_a_run_without_cool_downs_says_what_the_run_is(foreign_run, params_file, capsys):
    assert main(["cooldown", str(foreign_run), "--params", str(params_file)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("protocol: a cool-down sweep run (`benchlab run cooldown-sweep`): this is not a cool-down "
                        "sweep run (an imported run), it has no cool-down to fit") and len(err.splitlines()) == 1
