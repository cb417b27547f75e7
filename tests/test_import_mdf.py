"""`benchlab import` of MDF files written by another tool (asammdf, the way a bench recorder writes them), with a
mapping file, onto one grid; and a run exported to MF4 and imported back identifies to the same parameters."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import h5py
import numpy as np
import pytest

import benchlab
from benchlab.cli import main
from benchlab.importing.grid import resample

from identified import assert_same_parameters  # tests/identified.py

START = datetime(2026, 3, 2, 7, 45, 12, tzinfo=timezone.utc)
MAPPING = """
[channels]
engine_speed = "n_Motor"
clutch_speed = "n_Getriebe"
clutch_torque = "M_Kupplung"
clutch_state = "KU_Zustand"
load_torque = "M_Last"
T_air = "T_Luft"
T_ambient = "T_Umgebung"
T_flywheel = "T_Schwungrad"
[channels.T_housing]
source = "T_Gehaeuse"
group = 2
[channels.friction_power]
source = "P_Reib_raw"
unit = "kW"
scale = 0.001
"""
#: The temperature sample (2 Hz group, 100 s) the recorder marked invalid: dropped instead of NaN, it would be
#: bridged (its neighbours are two periods apart, within the grid's gap rule).
INVALID = 200


def _recorder_mdf(path, run, odd_unit="V"):
    """`run` as a bench recorder would log it (asammdf): a 100 Hz CAN group whose stamps are 4 ms off the grid, a
    20 Hz node group, a 2 Hz scanner group with invalidation bits, a master per group, vendor names and units;
    `T_Gehaeuse` in two groups (the mapping says which); `U_Fremd` in `odd_unit`."""
    from asammdf import MDF, Signal

    t = run["time"].to_numpy()
    can, node, scan = slice(None), slice(None, None, 5), slice(None, None, 50)
    col = {c: run[c].to_numpy() for c in run.columns}
    bits = np.zeros(len(t[scan]), dtype=bool)
    bits[INVALID % len(bits)] = True
    mdf = MDF(version="4.10")
    mdf.append([Signal(col["engine_speed"][can], t[can] + 0.004, unit="1/min", name="n_Motor"),
                Signal(col["clutch_speed"][can], t[can] + 0.004, unit="U/min", name="n_Getriebe"),
                Signal(col["clutch_torque"][can], t[can] + 0.004, unit="Nm", name="M_Kupplung"),
                Signal(col["clutch_state"][can].astype(np.uint8), t[can] + 0.004, unit="-", name="KU_Zustand"),
                Signal(col["load_torque"][can], t[can] + 0.004, unit="N·m", name="M_Last"),
                Signal(col["friction_power"][can], t[can] + 0.004, unit="", name="P_Reib_raw"),
                Signal(np.ones(len(t[can])), t[can] + 0.004, unit=odd_unit, name="U_Fremd")],
               acq_name="CAN1 100 Hz", comment="drive CAN")
    mdf.append([Signal(col["T_flywheel"][node], t[node], unit="°C", name="T_Schwungrad"),
                Signal(col["T_housing"][node] + 273.15, t[node], unit="K", name="T_Gehaeuse")],
               acq_name="node 20 Hz")
    mdf.append([Signal(col["T_air"][scan], t[scan], unit="°C", name="T_Luft", invalidation_bits=bits),
                Signal(col["T_ambient"][scan], t[scan], unit="°C", name="T_Umgebung", invalidation_bits=bits),
                Signal(col["T_housing"][scan] + 273.15, t[scan], unit="K", name="T_Gehaeuse")],
               acq_name="scanner 2 Hz")
    mdf.header.start_time = START
    mdf.header.comment = "Prüfstand 3, Kupplung K7, Messung 12"
    mdf.save(path, overwrite=True)
    mdf.close()


@pytest.fixture(scope="module")
def recorder_part(short_run):
    """The first 10 minutes of the simulated run."""
    return short_run[short_run["time"] < 600.0].reset_index(drop=True)


def test_a_recorders_mdf_with_a_mapping_becomes_a_run_file_identify_accepts(tmp_path, recorder_part):
    src, mapping, out = tmp_path / "messung.mf4", tmp_path / "map.toml", tmp_path / "r.h5"
    _recorder_mdf(src, recorder_part)
    mapping.write_text(MAPPING)
    assert main(["import", str(src), "--mapping", str(mapping), "--dt", "0.1", "--out", str(out)]) == 0
    run = benchlab.load_run(out)
    assert run.attrs["dt"] == pytest.approx(0.1) and run["time"].iloc[-1] == pytest.approx(599.99 - 0.01, abs=0.1)
    with h5py.File(out) as f:
        attrs = dict(f.attrs)
        units = {k: f["aligned"][k].attrs["units"] for k in f["aligned"]}
        # each source channel raw at its own rate, as the file held it (units, the invalid sample NaN)
        raw = {name: {k: g[k][()] for k in g} for name, g in f["raw"].items()}
        assert set(raw) == {"messung.CAN1 100 Hz", "messung.node 20 Hz", "messung.scanner 2 Hz"}
        assert f["raw/messung.scanner 2 Hz/T_Gehaeuse"].attrs["units"] == "K"
        assert "T_Luft" in f["aligned/T_air"].attrs["description"]
    assert [len(raw[g]["time"]) for g in sorted(raw)] == [60000, 12000, 1200]
    np.testing.assert_allclose(raw["messung.CAN1 100 Hz"]["time"][:2], [0.004, 0.014])
    assert np.flatnonzero(np.isnan(raw["messung.scanner 2 Hz"]["T_Luft"])).tolist() == [INVALID]
    np.testing.assert_allclose(raw["messung.scanner 2 Hz"]["T_Gehaeuse"],
                               recorder_part["T_housing"].to_numpy()[::50] + 273.15)
    assert set(raw["messung.node 20 Hz"]) == {"time", "T_Schwungrad"}  # the channels picked, not the group's all
    assert units == {**{k: "degC" for k in ("T_air", "T_ambient", "T_flywheel", "T_housing")}, "time": "s",
                     "engine_speed": "rpm", "clutch_speed": "rpm", "clutch_torque": "N*m", "load_torque": "N*m",
                     "clutch_state": "1", "friction_power": "W"}
    assert datetime.fromisoformat(attrs["created_utc"]) == START  # the scanner's first sample is at 0 s
    assert "Kupplung K7" in attrs["source_comment"] and attrs["source_file"] == "messung.mf4"
    picked = json.loads(attrs["source_channels"])
    assert picked["clutch_state"]["rule"] == "hold" and picked["T_air"]["rule"] == "interpolate"

    source = recorder_part.set_index(np.round(recorder_part["time"].to_numpy(), 6))
    grid = np.round(run["time"].to_numpy(), 6)
    on_scan = np.isin(grid, np.round(np.arange(0, 600, 0.5), 6))
    housing = source["T_housing"].reindex(grid).to_numpy()
    np.testing.assert_allclose(run["T_housing"].to_numpy()[on_scan], housing[on_scan], atol=1e-9)  # K → °C
    # the invalid scanner sample at 100 s is NaN, and so is the grid between it and its neighbours
    air = run["T_air"].to_numpy()
    assert np.isnan(air[(grid > 99.5) & (grid < 100.5)]).all()
    assert np.isfinite(air[(grid <= 99.5) | ((grid >= 100.5) & (grid <= 599.5))]).all()
    assert np.isnan(air[grid > 599.5]).all()  # after the scanner's last sample (the CAN group goes on to 599.994 s)
    state = run["clutch_state"].to_numpy()
    assert np.isnan(state[0]) and set(np.unique(state[1:])) == {0.0, 1.0}  # held; nothing before the CAN's 4 ms
    np.testing.assert_allclose(run["friction_power"].max(), recorder_part["friction_power"].max(), rtol=0.05)
    speed_err = run["engine_speed"].to_numpy() - source["engine_speed"].reindex(grid).to_numpy()
    assert np.nanmedian(np.abs(speed_err)) < 1.0  # 100 Hz interpolated 4 ms off: within a rpm

    assert main(["identify", str(out), "--model", "linear", "--out", str(tmp_path / "p.json"), "-q"]) == 0


def test_a_run_exported_to_mf4_and_imported_back_identifies_to_the_same_parameters(tmp_path, run_file):
    mf4, back = tmp_path / "run.mf4", tmp_path / "back.h5"
    assert main(["export", str(run_file), "--to", str(mf4)]) == 0
    assert main(["import", str(mf4), "--dt", "0.01", "--out", str(back)]) == 0
    assert_same_parameters(tmp_path, run_file, back)


@pytest.mark.parametrize("mapping, field", [
    ('[channels]\nT_air = "no_such_channel"', "channel T_air ← no_such_channel"),
    ('[channels]\nT_housing = "T_Gehaeuse"', "channel T_housing ← T_Gehaeuse"),    # in two groups
    ('[channels.T_air]\nsource = "M_Kupplung"', "channel T_air ← M_Kupplung [Nm]"),  # a temperature in N·m
    ('[channels.T_air]\nsource = "T_Luft"\nrule = "smooth"', "channels.T_air.rule"),
    ('[channels.T_air]\nsource = "T_Luft"\nscale = "2"', "channels.T_air.scale"),
    ('[channels.T_air]\nsorce = "T_Luft"', "channels.T_air.sorce"),
    # run-file channel names follow the model files' name rule (they become HDF5 paths and expression names)
    ('[channels]\n"a/b/c" = "T_Luft"', "'a/b/c'"), ('[channels]\n".." = "T_Luft"', "'..'"),
    ('[channels]\n"a\\u0000b" = "T_Luft"', "channels"), ('[channels]\n"<script>" = "T_Luft"', "'<script>'"),
    ('[channels]\n"" = "T_Luft"', "''"), ('[channels]\n"__class__" = "T_Luft"', "__class__"),
    ("[channels]\n" + "".join(f'e{i} = "T_Luft"\n' for i in range(10_000)), "at most 1000 channels, got 10000"),
])
def test_a_bad_mapping_is_one_line_naming_the_field(mapping, field, tmp_path, recorder_part, refused):
    src, path = tmp_path / "m.mf4", tmp_path / "map.toml"
    _recorder_mdf(src, recorder_part.iloc[:2000])
    path.write_text(mapping)
    refused(["import", str(src), "--mapping", str(path), "--dt", "0.1", "--out", str(tmp_path / "r.h5")], field)
    assert not (tmp_path / "r.h5").exists()


def test_an_mdf_needs_dt_and_its_required_channels(tmp_path, recorder_part, refused):
    src = tmp_path / "m.mf4"
    _recorder_mdf(src, recorder_part.iloc[:2000])
    refused(["import", str(src), "--out", str(tmp_path / "r.h5")], "--dt")
    err = refused(["import", str(src), "--dt", "0.1", "--out", str(tmp_path / "r.h5")], "channel", "--mapping",
                  "missing", "T_air", "n_Motor", "T_Luft", "U_Fremd")
    assert err.count("T_Gehaeuse") == 1 and "time" not in err.partition("offers")[2]   # each name once, no masters
    (tmp_path / "few.toml").write_text('[channels]\nT_air = "T_Luft"')
    err = refused(["import", str(src), "--mapping", str(tmp_path / "few.toml"), "--dt", "0.1", "--out",
                   str(tmp_path / "r.h5")], "channel engine_speed", "required", "n_Motor", "M_Kupplung")
    assert "T_air" not in err.partition("offers")[0]   # mapped, so not missing
    refused(["import", str(src), "--mapping", str(tmp_path / "few.toml"), "--dt", "1e-9", "--out",
             str(tmp_path / "r.h5")], "--dt", "rows")
    (tmp_path / "bad.mf4").write_bytes(b"not an MDF file at all" * 10)
    refused(["import", str(tmp_path / "bad.mf4"), "--dt", "0.1", "--out", str(tmp_path / "r.h5")], "file", "MDF")


def test_the_grid_rules_hold_interpolate_and_never_bridge_a_gap():
    stamps = np.array([0.0, 1.0, 2.0, 3.0, 10.0, 11.0])
    values = np.array([0.0, 1.0, np.nan, 3.0, 10.0, 11.0])
    grid = np.arange(-1.0, 15.0, 0.5)
    inter, hold = resample(stamps, values, grid, "interpolate"), resample(stamps, values, grid, "hold")
    at = dict(zip(grid, inter))
    assert at[0.5] == 0.5 and at[10.5] == 10.5 and at[3.0] == 3.0
    assert all(np.isnan(at[g]) for g in (-1.0, 1.5, 2.5, 3.5, 6.0, 9.5, 11.5))   # before, beside NaN, a gap, after
    held = dict(zip(grid, hold))
    assert held[0.5] == 0.0 and np.isnan(held[2.5]) and held[5.5] == 3.0 and np.isnan(held[6.5]) and held[14.0] == 11


@pytest.mark.parametrize("unit", ["10**10**10*K", "K/0", "(" * 5000 + "K" + ")" * 5000, "delta_degC", "1e309*K",
                                  "<script>", "no_such_unit"], ids=range(7))
@pytest.mark.parametrize("where", ["mapping, contract channel", "mapping, extra channel", "MF4 channel"])
def test_a_unit_that_is_no_unit_is_one_line_exit_2(unit, where, tmp_path, recorder_part, refused):
    src, path = tmp_path / "m.mf4", tmp_path / "map.toml"
    _recorder_mdf(src, recorder_part.iloc[:2000], odd_unit=unit if where == "MF4 channel" else "V")
    unit_toml = json.dumps(unit)
    extra = {"mapping, contract channel": f'[channels.T_air]\nsource = "T_Luft"\nunit = {unit_toml}',
             "mapping, extra channel": f'[channels.fremd]\nsource = "U_Fremd"\nunit = {unit_toml}',
             "MF4 channel": '[channels.fremd]\nsource = "U_Fremd"'}[where]
    path.write_text(MAPPING.replace('T_air = "T_Luft"\n', "") + "\n" + extra + "\n")
    refused(["import", str(src), "--mapping", str(path), "--dt", "0.1", "--out", str(tmp_path / "r.h5")],
            str(src), "T_air ← T_Luft" if where.endswith("contract channel") else "fremd ← U_Fremd")
    assert not (tmp_path / "r.h5").exists()
