"""`benchlab import` of CAN logs written by python-can's loggers (BLF, ASC) with the bench's DBC, merged with a
temperature logger's CSV on one clock; each source channel kept raw under /raw; the run rebuilt from its CAN
traffic and its temperatures identifies to the same parameters as the run itself."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import can
import h5py
import numpy as np
import pytest

import benchlab
from benchlab.cli import main
from benchlab.drivetrain import DrivetrainFacts, slipping_by_speed
from drivers.can_codec import compile_codecs
from drivers.can_frames import ERROR, join, make_frames
from drivers.can_log import log_frames
from drivers.can_signals import BENCH_DBC, CLAMP_CLAMPED, CLAMP_OPEN, CLAMP_SLIPPING, STATE_RUNNING

from identified import assert_same_parameters  # tests/identified.py

START = datetime(2026, 3, 2, 7, 45, 12, tzinfo=timezone.utc)
#: The temperature logger's clock reads this much ahead of the CAN log's (it was started that long before).
LOGGER_AHEAD_S = 3.0
TEMPERATURES = ("T_flywheel", "T_air", "T_housing", "T_ambient")


def _status_frames(run) -> np.ndarray:
    """The controllers' status frames of `run` at 100 Hz (the DBC's cycle), as the bench's DBC encodes them, on
    UNIX time from START: drive (speed), clutch actuator (torque, clamp state), load machine (speed at the load
    side, torque), each 1 ms after the one before."""
    import cantools

    codecs = compile_codecs(cantools.database.load_file(str(BENCH_DBC)))
    t = run["time"].to_numpy() + START.timestamp()
    n = len(t)
    engine, clutch = run["engine_speed"].to_numpy(), run["clutch_speed"].to_numpy()
    clamped = run["clutch_state"].to_numpy() > 0.5
    clamp = np.where(~clamped, CLAMP_OPEN, np.where(slipping_by_speed(engine, clutch), CLAMP_SLIPPING, CLAMP_CLAMPED))
    alive = np.arange(n) % 16
    rows = {"DriveMotor_Status": {"DM_Speed": engine, "DM_State": STATE_RUNNING, "DM_Alive": alive},
            "ClutchActuator_Status": {"CA_Torque": run["clutch_torque"].to_numpy(), "CA_ClampState": clamp,
                                      "CA_State": STATE_RUNNING, "CA_Alive": alive},
            "LoadMachine_Status": {"LM_Speed": clutch / DrivetrainFacts().gear_ratio,
                                   "LM_Torque": run["load_torque"].to_numpy(), "LM_State": STATE_RUNNING,
                                   "LM_Alive": alive}}
    parts = []
    for k, (name, signals) in enumerate(rows.items()):
        codec = codecs[name]
        values = np.zeros((n, codec.table.width))
        for j, key in enumerate(codec.columns):
            values[:, j] = signals.get(key, 0.0)
        payload = codec.table.encode(np.zeros(n, np.intp), values)[:, :codec.length]
        parts.append(make_frames(t + 0.001 * k, codec.message.frame_id, payload))
    frames = join(parts)
    return frames[np.argsort(frames["timestamp"], kind="stable")]


def _junk(t: float) -> np.ndarray:
    """An error frame, a frame of an id the DBC does not know and a clutch status frame cut to 3 bytes."""
    frames = join([make_frames(np.array([t]), 0x123, np.ones((1, 8), np.uint8)),
                   make_frames(np.array([t + 0.0002]), 273, np.ones((1, 3), np.uint8)),
                   make_frames(np.array([t + 0.0004]), 0, np.zeros((1, 8), np.uint8))])
    frames["flags"][2] |= ERROR
    return frames


@pytest.fixture(scope="module")
def logged(tmp_path_factory, short_run):
    """The run's CAN traffic as python-can's BLFWriter logs it (three bad frames in the middle), and its
    temperatures as a 2 Hz logger's CSV whose clock reads LOGGER_AHEAD_S ahead of the log's."""
    folder = tmp_path_factory.mktemp("canlog")
    frames = _status_frames(short_run)
    middle = len(frames) // 2
    frames = join([frames[:middle], _junk(float(frames["timestamp"][middle - 1]) + 1e-4), frames[middle:]])
    blf = folder / "bench.blf"
    with can.Logger(str(blf)) as writer:
        log_frames(writer, frames)
    scan = short_run.iloc[::50]
    csv = folder / "temperaturen.csv"
    table = scan[list(TEMPERATURES)].assign(time=scan["time"] + LOGGER_AHEAD_S)[["time", *TEMPERATURES]]
    table.rename(columns={"time": "time [s]", **{c: f"{c} [°C]" for c in TEMPERATURES}}).to_csv(
        csv, index=False, sep=";", decimal=",")
    return blf, csv


def test_a_run_rebuilt_from_its_blf_log_and_its_temperatures_identifies_to_the_same_parameters(
        tmp_path, logged, run_file, short_run, capsys):
    blf, csv = logged
    out = tmp_path / "rebuilt.h5"
    assert main(["import", str(blf), str(csv), "--dt", "0.01", "--offset", f"{csv.name}={-LOGGER_AHEAD_S}",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for what in ("error or remote frames: 1", "ids the DBC does not know: 1", "shorter than their message: 1"):
        assert what in printed, printed
    run = benchlab.load_run(out)
    with h5py.File(out) as f:
        attrs = dict(f.attrs)
        raw = {name: set(group) for name, group in f["raw"].items()}
        assert f["raw/bench.LoadMachine_Status"].attrs["node"] == "LoadMachine"
        assert f["raw/bench.LoadMachine_Status/LM_Speed"].attrs["units"] == "rpm"
        described = f["aligned/clutch_speed"].attrs["description"]
        assert len(f["raw/temperaturen/T_air"]) == len(f["raw/temperaturen/time"]) < len(run) / 40  # 2 Hz
    assert raw["bench.DriveMotor_Status"] == {"time", "DM_Speed"}
    assert "LM_Speed" in described and "bench.blf" in described
    assert datetime.fromisoformat(attrs["created_utc"]) == START
    assert json.loads(attrs["import_skipped"])["bench.blf: frames of ids the DBC does not know"] == 1
    # on one clock: the logger's readings sit where the run had them (2 Hz, interpolated between)
    grid = run["time"].to_numpy()
    for name in TEMPERATURES:
        on_scan = np.isin(np.round(grid, 6), np.round(np.arange(0.0, grid[-1], 0.5), 6))
        np.testing.assert_allclose(run[name].to_numpy()[on_scan], short_run[name].to_numpy()[:len(grid)][on_scan],
                                   atol=1e-9, err_msg=name)
    energy = [np.nansum(r["friction_power"].to_numpy()) * 0.01 for r in (run, short_run)]
    assert energy[0] == pytest.approx(energy[1], rel=0.02)

    assert_same_parameters(tmp_path, run_file, out)


@pytest.mark.parametrize("suffix", [".asc", ".trc", ".log", ".mf4"])
def test_a_log_from_python_cans_writers_imports_with_a_mapping(suffix, tmp_path, short_run):
    """A vendor-style mapping names DBC signals (MESSAGE.SIGNAL or SIGNAL) for contract channels; each of
    python-can's log formats (an ASC log in relative time, an MF4 of bus logging, ...) starts where the CSV's
    clock does."""
    part = short_run.iloc[:1000]
    frames = _status_frames(part)
    asc, csv, mapping, out = tmp_path / f"bus{suffix}", tmp_path / "t.csv", tmp_path / "map.toml", tmp_path / "r.h5"
    with can.Logger(str(asc)) as writer:
        log_frames(writer, frames)
    part[["time", *TEMPERATURES, "friction_power", "clutch_state"]].to_csv(csv, index=False)
    mapping.write_text('[channels]\nengine_speed = "DM_Speed"\nload_torque = "LoadMachine_Status.LM_Torque"\n'
                       '[channels.clutch_speed]\nsource = "LM_Speed"\nscale = 15.0\n'
                       '[channels.clutch_torque]\nsource = "CA_Torque"\nunit = "kN*m"\nscale = 0.001\n')
    assert main(["import", str(asc), str(csv), "--mapping", str(mapping), "--dt", "0.01", "--out", str(out)]) == 0
    run = benchlab.load_run(out)
    rows = min(len(run), len(part)) - 5
    frame_time = part["time"].to_numpy() + 0.001  # the clutch actuator's frames, 1 ms after the drive's
    torque = np.interp(run["time"].to_numpy(), frame_time, part["clutch_torque"].to_numpy())  # the stated rule
    np.testing.assert_allclose(run["clutch_torque"].to_numpy()[1:rows], torque[1:rows], atol=0.01)
    np.testing.assert_allclose(run["engine_speed"].to_numpy()[1:rows], part["engine_speed"].to_numpy()[1:rows],
                               atol=0.3)
    np.testing.assert_array_equal(run["clutch_state"].to_numpy()[:rows], part["clutch_state"].to_numpy()[:rows])


def test_bad_can_inputs_are_one_line(tmp_path, logged, refused):
    blf, csv = logged
    out = str(tmp_path / "r.h5")
    refused(["import", str(blf), str(csv), "--out", out], "--dt")
    refused(["import", str(blf), str(csv), "--dt", "0.01", "--offset", "nofile.csv=3", "--out", out], "--offset")
    refused(["import", str(blf), str(csv), "--dt", "0.01", "--offset", f"{csv.name}=1e12", "--out", out],
            "--offset")
    (tmp_path / "bad.dbc").write_text("BO_ this is not a DBC")
    refused(["import", str(blf), "--dbc", str(tmp_path / "bad.dbc"), "--dt", "0.01", "--out", out], "bad.dbc")
    (tmp_path / "m.toml").write_text('[channels]\nT_air = "NoSuchSignal"\n')
    refused(["import", str(blf), str(csv), "--mapping", str(tmp_path / "m.toml"), "--dt", "0.01", "--out", out],
            "channel T_air ← NoSuchSignal")
    (tmp_path / "empty.blf").write_bytes(b"LOGG" + bytes(200))
    refused(["import", str(tmp_path / "empty.blf"), "--dt", "0.01", "--out", out], "empty.blf")


def test_a_blf_log_corrupt_part_way_keeps_the_frames_before(tmp_path, logged, capsys):
    blf, csv = logged
    data = bytearray(blf.read_bytes())
    data[len(data) // 2:len(data) // 2 + 100] = b"x" * 100  # inside a compressed container
    bad, out = tmp_path / "bad.blf", tmp_path / "r.h5"
    bad.write_bytes(bytes(data))
    assert main(["import", str(bad), str(csv), "--dt", "0.01", "--offset", f"{csv.name}={-LOGGER_AHEAD_S}",
                 "--out", str(out)]) == 0
    assert "unreadable rest of the file: 1 skipped" in capsys.readouterr().out
    run = benchlab.load_run(out)
    speed = run["engine_speed"].to_numpy()
    last = int(np.flatnonzero(np.isfinite(speed))[-1])
    assert 0.2 * len(run) < last < 0.8 * len(run) and np.isnan(speed[last + 1:]).all()  # never bridged or made up
    assert np.isfinite(run["T_air"].to_numpy()[-100:]).all()  # the logger's readings go on
