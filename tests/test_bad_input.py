"""Bad input on the command line and in run or bench files: exit 2, one line naming file or field, no traceback.

Issue 12: numbers a bench cannot do are refused at parse time (they used to hang with growing memory), and
inputs that used to end in exit 1 with a Python error name what was expected instead.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from benchlab.bounds import BENCH_NUMBER_RANGES, MAX_CYCLES, MAX_RUN_DURATION_S, MAX_SCAN_CHANNELS, MAX_TIMEOUT_S
from benchlab.cli import main
from benchlab.runfile import load_run
from benchlab.runner.config import load_bench_config
from drivers.can_signals import BENCH_DBC

EXAMPLE_BENCH = Path(__file__).resolve().parents[1] / "examples" / "bench.toml"


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
    _refused(["run", "table1", "--bench", "sim", "--duration", value, "--out", str(tmp_path / "r.h5")], "--duration",
             capsys)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("value", ["1000000000", "0", "-1", "1.5", str(MAX_CYCLES + 1)])
def test_run_cycles_out_of_bounds_is_refused(value, tmp_path, capsys):
    _refused(["run", "table1", "--bench", "sim", "--cycles", value, "--out", str(tmp_path / "r.h5")], "--cycles",
             capsys)


def test_schedule_longer_than_the_longest_run_is_refused_before_anything_moves(tmp_path, capsys):
    err = _refused(["run", "table1", "--bench", "sim", "--cycles", str(MAX_CYCLES), "--out", str(tmp_path / "r.h5")],
                   "schedule",
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
    (["run", "table1", "--bench", "sim", "--seed", "-1"], "--seed"),
    (["identify", "RUN", "--starts", "0", "--out", "p.json"], "--starts"),
    (["identify", "RUN", "--seed", "-3", "--out", "p.json"], "--seed"),
    (["pipeline", "--duration", "inf"], "--duration"),
    (["pipeline", "--duration", "-60"], "--duration"),
    (["pipeline", "--seed", "-2"], "--seed"),
    (["wear", "RUN", "--params", "p.json", "--paths", "0"], "--paths"),
    (["wear", "RUN", "--params", "p.json", "--paths", "1000000000"], "--paths"),
    (["wear", "RUN", "--params", "p.json", "--predict", "1e20"], "--predict"),
    (["wear", "RUN", "--params", "p.json", "--predict", "-4"], "--predict"),
    (["cooldown", "RUN", "--params", "p.json", "--sample", "nan"], "--sample"),
    (["cooldown", "RUN", "--params", "p.json", "--sample", "1e9"], "--sample"),
    (["run", "table1", "--bench", "sim", "--realtime", "1e-9"], "--realtime"),  # a 60 s run over 1900 years
    (["run", "table1", "--bench", "sim", "--realtime", "1e-300"], "--realtime"),  # was an OverflowError
    (["diagnose", "RUN", "--group-by", ""], "--group-by"),
    (["batch", "identify", "RUN", "--out", "d", "--group-by", ""], "--group-by"),
])
def test_counts_and_seeds_are_checked(argv, field, tmp_path, capsys):
    argv = [str(tmp_path / "run.h5") if a == "RUN" else a for a in argv]
    _refused(argv + (["--out", str(tmp_path / "r.h5")] if argv[0] == "run" else []), field, capsys)


# -- run files: checked once, where they are read (benchlab.runfile.load_run) --------------------------------

def _edit_channel(path, name: str, index, value: float) -> None:
    """Set samples of one /aligned channel, rewritten as float64 (1e300 does not fit the fixture's float32)."""
    with h5py.File(path, "a") as f:
        values = f["aligned"][name][()].astype(np.float64)
        values[index] = value
        units = f["aligned"][name].attrs["units"]
        del f["aligned"][name]
        f["aligned"].create_dataset(name, data=values).attrs["units"] = units


BAD_VALUES = {  # case: (channel, samples, value, field named)
    "inf engine speed": ("engine_speed", 100, np.inf, "/aligned/engine_speed"),
    "-inf clutch speed": ("clutch_speed", 5, -np.inf, "/aligned/clutch_speed"),
    "1e300 friction power": ("friction_power", 7, 1e300, "/aligned/friction_power"),
    "1e30 clutch torque": ("clutch_torque", 9, 1e30, "/aligned/clutch_torque"),
    "inf ambient": ("T_ambient", 3, np.inf, "/aligned/T_ambient"),
    "clutch state 3": ("clutch_state", 50, 3.0, "/aligned/clutch_state"),
    "clutch state 0.5": ("clutch_state", 51, 0.5, "/aligned/clutch_state"),
    "clutch state -0.2": ("clutch_state", 52, -0.2, "/aligned/clutch_state"),
}


@pytest.mark.parametrize("case", sorted(BAD_VALUES))
@pytest.mark.parametrize("command", ["simulate", "identify", "wear"])
def test_unmeasurable_values_in_a_run_file_are_refused(case, command, foreign_run, params_file, tmp_path, capsys):
    channel, index, value, field = BAD_VALUES[case]
    _edit_channel(foreign_run, channel, index, value)
    argv = {"simulate": ["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
            "identify": ["identify", str(foreign_run), "--model", "linear", "--out", str(tmp_path / "fit.json")],
            "wear": ["wear", str(foreign_run), "--params", str(params_file)]}[command]
    err = _refused(argv, field, capsys)
    assert str(foreign_run) in err and f"at sample {index}" in err


def test_clutch_state_noise_is_not_a_third_state(foreign_run, params_file, tmp_path, capsys):
    _edit_channel(foreign_run, "clutch_state", [10, 11, 12], [1.04, -0.03, np.nan])
    code, err = _cli(["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
                     capsys)
    assert code == 0, err


@pytest.mark.parametrize("dt", ["0.1", np.bytes_(b"0.1"), True, np.array([0.1, 0.1])])
def test_dt_that_is_not_a_number_is_refused(dt, foreign_run, params_file, tmp_path, capsys):
    with h5py.File(foreign_run, "a") as f:
        f["aligned"].attrs["dt"] = dt
    err = _refused(["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
                   "/aligned.dt", capsys)
    assert str(foreign_run) in err and "a positive time step" in err


@pytest.mark.parametrize("channel", ["T_flywheel", "T_air", "T_housing"])
@pytest.mark.parametrize("command", ["identify", "diagnose", "simulate"])
def test_all_nan_target_channel_is_refused(channel, command, foreign_run, params_file, tmp_path, capsys):
    _edit_channel(foreign_run, channel, slice(None), np.nan)
    argv = {"simulate": ["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
            "identify": ["identify", str(foreign_run), "--model", "linear", "--out", str(tmp_path / "fit.json")],
            "diagnose": ["diagnose", str(foreign_run)]}[command]
    err = _refused(argv, f"/aligned/{channel}", capsys)
    assert str(foreign_run) in err and "all 300 are NaN" in err
    assert not (tmp_path / "s.h5").exists() and not (tmp_path / "fit.json").exists()


def test_a_dead_sensor_is_still_a_readable_run_file(foreign_run):
    _edit_channel(foreign_run, "T_air", slice(None), np.nan)  # a run that lost its air sensor: the file is fine
    assert load_run(foreign_run)["T_air"].isna().all()


# -- output files ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", ["run", "simulate", "identify", "import", "wear"])
def test_output_file_in_a_missing_directory_is_refused(command, foreign_run, params_file, tmp_path, capsys):
    out = str(tmp_path / "missing" / "out.x")
    argv = {"run": ["run", "table1", "--bench", "sim", "--cycles", "1", "--out", out],
            "simulate": ["simulate", str(foreign_run), "--params", str(params_file), "--out", out],
            "identify": ["identify", str(foreign_run), "--out", out],
            "import": ["import", str(tmp_path / "d.csv"), "--out", out],
            "wear": ["wear", str(foreign_run), "--params", str(params_file), "--plot", out]}[command]
    err = _refused(argv, "--out" if command != "wear" else "--plot", capsys)
    assert "missing" in err and "existing directory" in err
    assert not (tmp_path / "missing").exists()


# -- BENCH.toml ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("dbc_text, expected", [
    ("not a dbc at all\n", "cantools can load"),
    ('VERSION ""\n\nBO_ 5 Foo: 8 PC\n SG_ X : 0|8@1+ (1,0) [0|255] "" PC\n', "DriveMotor_Cmd"),
])
def test_bench_file_dbc_that_is_not_the_bench_dbc_is_refused(dbc_text, expected, tmp_path, capsys):
    (tmp_path / "vendor.dbc").write_text(dbc_text)
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace('bitrate = 500000', 'bitrate = 500000\ndbc = "vendor.dbc"'))
    err = _refused(["run", "table1", "--bench", str(bench), "--cycles", "1", "--out", str(tmp_path / "r.h5")],
                   "can.dbc", capsys)
    assert str(bench) in err and expected in err and not (tmp_path / "r.h5").exists()


def test_bench_file_with_the_bench_dbc_passes_the_check(tmp_path):
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace('bitrate = 500000', f'bitrate = 500000\ndbc = "{BENCH_DBC}"'))
    assert load_bench_config(bench).dbc == str(BENCH_DBC)


@pytest.mark.parametrize("value", ["1e12", "700.0"])
def test_bench_file_absurd_timeout_is_refused(value, tmp_path, capsys):
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace("timeout_s = 2.0", f"timeout_s = {value}"))
    _refused(["run", "table1", "--bench", str(bench), "--cycles", "1", "--out", str(tmp_path / "r.h5")],
             "instrument.timeout_s", capsys)


def test_bench_file_drivetrain_is_the_one_the_limits_estimate_launches_with(tmp_path):
    """[drivetrain] is the only home of gear ratio and load inertia: the CAN bench and the limits read the same."""
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace("gear_ratio = 15.0", "gear_ratio = 10.0")
                     .replace("load_inertia_kgm2 = 70.0", "load_inertia_kgm2 = 40.0"))
    config = load_bench_config(bench)
    assert config.drivetrain.gear_ratio == config.limits.drivetrain.gear_ratio == 10.0
    assert config.limits.drivetrain.inertia_at_clutch == pytest.approx(40.0 / 10.0 ** 2)


@pytest.mark.parametrize("table, line, field", [("drivetrain", "inertia = 70.0", "drivetrain.inertia"),
                                                 ("limits", "gear_ratio = 15.0", "limits.gear_ratio"),
                                                 ("drivetrain", "gear_ratio = -15.0", "drivetrain.gear_ratio")])
def test_bench_file_drivetrain_fact_in_the_wrong_place_or_sign_is_refused(table, line, field, tmp_path, capsys):
    text = EXAMPLE_BENCH.read_text()
    if table == "drivetrain":
        text = text.replace("gear_ratio = 15.0", line)
    else:
        text = text.replace("[limits]", f"[limits]\n{line}")
    bench = tmp_path / "bench.toml"
    bench.write_text(text)
    err = _refused(["run", "table1", "--bench", str(bench), "--cycles", "1", "--out", str(tmp_path / "r.h5")],
                   field, capsys)
    assert str(bench) in err and not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("line, typo, field", [
    ("fast_tick_s = 0.02", "fast_tick = 0.005", "acquisition.fast_tick"),
    ("tick_s = 0.1 ", "tick = 0.05 ", "acquisition.tick"),
    ("period_s = 0.2 ", "period = 0.1 ", "instrument.period"),
    ("timeout_s = 2.0", "timeout = 1.0", "instrument.timeout"),
    ("period_s = 0.05", "period_ms = 20", "node.period_ms"),
])
def test_bench_file_misspelt_key_is_refused_not_left_at_its_default(line, typo, field, tmp_path, capsys):
    """[acquisition] sets how often the interlocks are polled, [instrument] and [node] how often and how long the
    temperatures they watch are read: a misspelt key there used to run the bench at the default unnoticed."""
    text = EXAMPLE_BENCH.read_text()
    assert text.count(line) == 1
    bench = tmp_path / "bench.toml"
    bench.write_text(text.replace(line, typo))
    err = _refused(["run", "table1", "--bench", str(bench), "--cycles", "1", "--out", str(tmp_path / "r.h5")],
                   field, capsys)
    assert str(bench) in err and "(unknown key)" in err and not (tmp_path / "r.h5").exists()


def test_bench_file_can_table_takes_python_can_keys(tmp_path):
    """[can] is passed to can.Bus whole: its keys are python-can's, not benchlab's to refuse."""
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace("bitrate = 500000", "bitrate = 500000\nreceive_own_messages = false"))
    assert load_bench_config(bench).can["receive_own_messages"] is False


@pytest.mark.parametrize("channel, value",
                         [("engine_speed", "inf"), ("friction_power", "1e300"), ("clutch_state", "2")])
def test_import_refuses_what_load_run_would_refuse(channel, value, foreign_run, tmp_path, capsys):
    csv = tmp_path / "d.csv"
    frame = load_run(foreign_run)
    frame[channel] = frame[channel].astype(object)
    frame.loc[4, channel] = value
    frame.to_csv(csv, index=False)
    err = _refused(["import", str(csv), "--out", str(tmp_path / "r.h5")], f"column {channel}, line 6", capsys)
    assert str(csv) in err and not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("where", ["params", "clutch"])
def test_an_integer_beyond_a_float_in_a_user_file_is_bad_input_not_a_crash(where, tmp_path):
    """TOML and JSON integers have any size; float() of 10**400 overflows (one check: benchlab.values)."""
    import json
    import re

    from benchlab.errors import InputError
    from benchlab.model.params import load_params
    from benchlab.wear.clutchfile import load_clutch

    huge = str(10 ** 400)
    if where == "params":
        path = tmp_path / "p.json"
        path.write_text(json.dumps({"model": "linear", "params": {"C_P": 1}}).replace(": 1}", f": {huge}}}"))
        with pytest.raises(InputError, match="C_P"):
            load_params(path)
    else:
        path = tmp_path / "c.toml"
        example = Path(__file__).resolve().parents[1] / "examples" / "clutch.toml"
        edited, count = re.subn(r"(?m)^(faces_per_side|friction_faces|area_mm2|z)\s*=\s*\S+", lambda m: f"{m.group(1)} = {huge}",
                                example.read_text(), count=1)
        assert count == 1
        path.write_text(edited)
        with pytest.raises(InputError):
            load_clutch(path)


@pytest.mark.parametrize("section, line, field, says", [
    ("limits", "idle_speed_rpm = 5000.0", "limits.idle_speed_rpm", "below max_engine_speed_rpm (3000)"),
    ("limits", "max_flywheel_c = 1e300", "limits.max_flywheel_c", "from 30 to 400 degC"),
    ("limits", "max_flywheel_c = 450.0", "limits.max_flywheel_c", "from 30 to 400 degC"),
    ("limits", "max_air_c = 20.0", "limits.max_air_c", "from 30 to 200 degC"),
    ("limits", "max_clutch_torque_nm = 700.0", "limits.max_clutch_torque_nm", "the DBC's 600 N*m"),
    ("limits", "max_load_torque_nm = 5000.0", "limits.max_load_torque_nm", "the DBC's 3000 N*m"),
    ("limits", "max_engine_speed_rpm = 20000.0", "limits.max_engine_speed_rpm", "the DBC's 16000 rpm"),
    ("limits", "max_slip_time_s = 1e6", "limits.max_slip_time_s", "at most 60 s"),
    ("limits", "max_slip_energy_j = 1e12", "limits.max_slip_energy_j", "at most max_clutch_torque_nm"),
    ("limits", "max_wait_s = 1e9", "limits.max_wait_s", "at most 3600 s"),
    ("limits", "resume_after_s = 1e9", "limits.resume_after_s", "at most 3600 s"),
    ("limits", "clear_margin_k = 500.0", "limits.clear_margin_k", "at most 50 K"),
    ("acquisition", "flush_every_s = 1e9", "acquisition.flush_every_s", "at most 1"),
    ("limits.max_age_s", "T_air = 1.0", "limits.max_age_s.T_air", "more than 2 s"),
    ("limits.max_age_s", "engine_speed = 0.015", "limits.max_age_s.engine_speed", "more than 0.02 s"),
    ("limits.max_age_s", "T_flywheel = 0.05", "limits.max_age_s.T_flywheel", "more than 0.1 s"),
    ("acquisition", "tick_s = 5.0", "acquisition.tick_s", "at most 0.5"),
    ("limits.actions", "slip_time = { stages = [\"open_idle\"] }", "limits.actions.slip_time.stages", "ending in stop_hold"),
    ("limits.actions", "slip_time = { stages = [\"brake\", \"stop_hold\"] }", "limits.actions.slip_time.stages",
     "distinct safe states"),
    ("limits.actions", "slip_time = { escalate_after_s = 600 }", "limits.actions.slip_time.escalate_after_s",
     "at most 10"),
])
def test_bench_file_limits_against_physics_and_each_other_are_refused_at_dry_run(section, line, field, says,
                                                                                 tmp_path, capsys):
    """Issue 29: BENCH.toml's limits are checked against each other, the DBC and what sensors and materials allow,
    at --dry-run, before anything opens (a limit of 1e300 would switch its interlock off)."""
    key = line.split(" = ")[0]
    lines = [text for text in EXAMPLE_BENCH.read_text().splitlines() if not text.startswith(f"{key} = ")]
    at = lines.index(next(text for text in lines if text.startswith(f"[{section}]"))) + 1
    bench = tmp_path / "bench.toml"
    bench.write_text("\n".join(lines[:at] + [line] + lines[at:]) + "\n")
    err = _refused(["run", "table1", "--bench", str(bench), "--dry-run"], field, capsys)
    assert str(bench) in err and says in err, err


def test_bench_file_actions_table_sets_the_reaction_of_its_interlock(tmp_path):
    bench = tmp_path / "bench.toml"
    bench.write_text(EXAMPLE_BENCH.read_text().replace(
        'stale_T_air = "hold"', 'stale_T_air = "hold"\nslip_time = { then = "abort", stages = ["open_stop", '
                                '"stop_hold"], escalate_after_s = 1.5 }'))
    limits = load_bench_config(bench).limits
    assert limits.action("slip_time") == "abort" and limits.reaction("slip_time").stages == ("open_stop", "stop_hold")
    assert limits.reaction("slip_time").escalate_after_s == 1.5 and limits.action("stale_T_air") == "hold"


@pytest.mark.parametrize("dry_run", [False, True])
def test_run_params_file_is_read_and_checked_before_the_protocol_runs(dry_run, tmp_path, capsys):
    """Issue 29: `--params /nonexistent.json` used to run the whole cool-down sweep (hours on hardware), then exit 2."""
    out = tmp_path / "r.h5"
    err = _refused(["run", "cooldown-sweep", "--bench", "sim", "--out", str(out), "--params", str(tmp_path / "no.json")]
                   + (["--dry-run"] if dry_run else []), "no.json", capsys)
    assert "not found" in err and not out.exists() and not list(tmp_path.glob("*.lock")) and not list(tmp_path.glob("*.blf"))


def _bench_with(tmp_path: Path, field: str, value: str) -> Path:
    """The example BENCH.toml with one `table.key` set to `value` (the key's line in its table replaced)."""
    table, key = field.rsplit(".", 1)
    lines, inside = EXAMPLE_BENCH.read_text().splitlines(), False
    for i, line in enumerate(lines):
        if line.startswith("["):
            inside = line.split("#")[0].strip() == f"[{table}]"
        elif inside and line.split("=")[0].strip() == key:
            lines[i] = f"{key} = {value}"
            break
    else:
        raise AssertionError(f"{field} not in {EXAMPLE_BENCH}")
    bench = tmp_path / "bench.toml"
    bench.write_text("\n".join(lines) + "\n")
    return bench


@pytest.mark.parametrize("field", sorted(BENCH_NUMBER_RANGES))
@pytest.mark.parametrize("side", ["below", "above"])
def test_bench_file_number_beyond_its_physical_range_is_refused(field, side, tmp_path, capsys):
    low, high = BENCH_NUMBER_RANGES[field]
    value = low / 1000 if side == "below" else high * 1000
    if "baudrate" in field:
        value = int(value) if side == "above" else 1
    bench = _bench_with(tmp_path, field, repr(value))
    err = _refused(["run", "table1", "--bench", str(bench), "--dry-run"], field, capsys)
    assert str(bench) in err and f"{low:g} to {high:g}" in err


def test_a_tiny_gear_ratio_is_refused_not_a_dry_run_that_never_ends(tmp_path, capsys):
    bench = _bench_with(tmp_path, "drivetrain.gear_ratio", "1e-300")
    _refused(["run", "table1", "--bench", str(bench), "--dry-run"], "drivetrain.gear_ratio", capsys)


@pytest.mark.parametrize("field, url, words", [
    ("instrument.url", '"TCPIP0::10.0.0.5\\u0000::inst0::INSTR"', "printable"),
    ("instrument.url", '"TCPIP0::::INSTR"', "VISA resource"),
    ("instrument.url", '"TCPIP0::10.0.0.5::99999999::SOCKET"', "port from 1 to 65535"),
    ("instrument.url", '"GPIB0::99::INSTR"', "GPIB address"),
    ("node.url", '"socket://127.0.0.1:99999999"', "port from 1 to 65535"),
    ("node.url", '"garbage"', "device path"),
    ("node.url", '"ftp://host/x"', "pyserial URL scheme"),
])
def test_dry_run_checks_device_addresses_as_probe_does(field, url, words, tmp_path, capsys):
    """`run --dry-run` opens no device, but an address no device can have is refused as probe refuses it."""
    bench = _bench_with(tmp_path, field, url)
    dry = _refused(["run", "table1", "--bench", str(bench), "--dry-run"], field, capsys)
    probe = _refused(["probe", "--bench", str(bench)], field, capsys)
    assert words in dry and dry.split(": ", 1)[1] == probe.split(": ", 1)[1]
