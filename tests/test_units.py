"""Units as engineers write them (benchlab/units.py): read, converted to the contract's, clashes refused."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import benchlab
from benchlab import units
from benchlab.cli import main


@pytest.mark.parametrize("unit, target, one", [
    ("°C", "degC", 1.0), ("℃", "degC", 1.0), ("K", "degC", 1.0 - 273.15), ("degF", "degC", (1.0 - 32) * 5 / 9),
    ("Nm", "N*m", 1.0), ("N m", "N*m", 1.0), ("N·m", "N*m", 1.0), ("kN·m", "N*m", 1000.0), ("kNm", "N*m", 1000.0),
    ("1/min", "rpm", 1.0), ("U/min", "rpm", 1.0), ("Upm", "rpm", 1.0), ("min^-1", "rpm", 1.0),
    ("rad/s", "rpm", 30 / np.pi),
    ("kW", "W", 1000.0), ("ms", "s", 1e-3), ("min", "s", 60.0), ("h", "s", 3600.0), ("-", "1", 1.0),
])
def test_engineers_spellings_convert_to_the_contract_unit(unit, target, one):
    got = units.convert(np.array([1.0, np.nan]), unit, target)
    assert got[0] == pytest.approx(one, rel=1e-12) and np.isnan(got[1])
    assert units.same(unit, target) == (one == 1.0)


@pytest.mark.parametrize("unit, target", [("Nm", "degC"), ("degC", "N*m"), ("A", "rpm"), ("parsec/fortnight", "W"),
                                          ("no such unit", "degC")])
def test_a_unit_of_another_dimension_is_refused(unit, target):
    with pytest.raises(units.UnitMismatch, match=repr(unit)):
        units.convert(np.ones(2), unit, target)


def _german(part):
    """`part` as a German spreadsheet would hold it: vendor units in the titles, K, kW, 1/min, Nm."""
    return part.drop(columns="time").assign(
        T_housing=part["T_housing"] + 273.15, friction_power=part["friction_power"] / 1000.0).rename(columns={
            "T_air": "T_air [°C]", "T_flywheel": "T_flywheel [°C]", "T_ambient": "T_ambient [℃]",
            "T_housing": "T_housing [K]", "clutch_torque": "clutch_torque [Nm]", "load_torque": "load_torque [N·m]",
            "engine_speed": "engine_speed [1/min]", "clutch_speed": "clutch_speed [U/min]",
            "friction_power": "friction_power [kW]", "clutch_state": "clutch_state [-]"})


def test_a_german_excel_csv_imports_like_benchlabs_own_spelling(tmp_path, short_run):
    part = short_run.iloc[:400]
    german, own = tmp_path / "messung.csv", tmp_path / "own.csv"
    _german(part).to_csv(german, index=False, sep=";", decimal=",", encoding="utf-8-sig")
    part.drop(columns="time").to_csv(own, index=False)
    assert ";" in german.read_text(encoding="utf-8-sig").splitlines()[1]
    assert main(["import", str(german), "--out", str(tmp_path / "g.h5"), "--dt", "0.01"]) == 0
    assert main(["import", str(own), "--out", str(tmp_path / "o.h5"), "--dt", "0.01"]) == 0
    g, o = benchlab.load_run(tmp_path / "g.h5"), benchlab.load_run(tmp_path / "o.h5")
    assert list(g.columns) == list(o.columns) and g.attrs["units"] == o.attrs["units"]
    for name in o.columns:
        np.testing.assert_allclose(g[name].to_numpy(), o[name].to_numpy(), rtol=1e-12, atol=1e-9, err_msg=name)
    with h5py.File(tmp_path / "g.h5") as f:
        assert {k: f["aligned"][k].attrs["units"] for k in ("T_housing", "clutch_torque", "engine_speed")} == {
            "T_housing": "degC", "clutch_torque": "N*m", "engine_speed": "rpm"}


def test_a_dimension_clash_names_the_file_and_column(tmp_path, short_run, refused):
    csv = tmp_path / "d.csv"
    short_run.iloc[:20].drop(columns="time").rename(columns={"T_housing": "T_housing [Nm]"}).to_csv(csv, index=False)
    line = refused(["import", str(csv), "--out", str(tmp_path / "r.h5"), "--dt", "0.01"], str(csv),
                   "column T_housing [Nm]", "degC", "torque")
    assert not (tmp_path / "r.h5").exists(), line


def test_a_run_file_may_spell_the_contract_units_its_own_way(foreign_run):
    with h5py.File(foreign_run, "a") as f:
        f["aligned/T_air"].attrs["units"], f["aligned/clutch_torque"].attrs["units"] = "°C", "Nm"
    run = benchlab.load_run(foreign_run)
    assert run.attrs["units"]["T_air"] == "degC" and run.attrs["units"]["clutch_torque"] == "N*m"


def test_channels_beyond_the_contract_keep_their_unit_but_temperatures_are_degc(tmp_path, short_run):
    csv = tmp_path / "d.csv"
    part = short_run.iloc[:20].drop(columns="time").assign(rotor=300.15, stator=20.5, speed=1500.0, IqFbk=12.5)
    part.rename(columns={"rotor": "rotor [K]", "stator": "stator [°C]", "speed": "speed [1/min]",
                         "IqFbk": "IqFbk [A]"}).to_csv(csv, index=False, sep=";", decimal=",")
    assert main(["import", str(csv), "--out", str(tmp_path / "r.h5"), "--dt", "0.01"]) == 0
    run = benchlab.load_run(tmp_path / "r.h5")
    assert {k: run.attrs["units"][k] for k in ("rotor", "stator", "speed", "IqFbk")} == {
        "rotor": "degC", "stator": "degC", "speed": "rpm", "IqFbk": "A"}  # a model's temperatures are in degC
    np.testing.assert_allclose(run["rotor"], 27.0, atol=1e-9)


def test_figures_show_the_units_people_write_files_keep_the_stored_spelling():
    assert [units.display(u) for u in ("degC", "N*m", "rpm", "A", "1")] == ["°C", "N·m", "rpm", "A", "-"]


#: Unit texts a hostile or careless sender writes: a number tower pint would evaluate forever, a division by zero,
#: nesting past pint's recursion, an offset difference, a scale that is no finite positive number, markup, nonsense.
NOT_UNITS = ["10**10**10*K", "K/0", "(" * 5000 + "K" + ")" * 5000, "delta_degC", "1e309*K", "nan*K", "0*K",
             "<script>alert(1)</script>", "no_such_unit", "K^99", "((((K))))", "K/", "*K"]


@pytest.mark.parametrize("unit", NOT_UNITS, ids=range(len(NOT_UNITS)))
def test_a_text_that_is_no_unit_is_refused_before_or_by_pint(unit):
    with pytest.raises(units.UnitMismatch, match="degC or a unit convertible to it"):
        units.convert(np.ones(2), unit, "degC")
    assert not units.same(unit, "degC")


@pytest.mark.parametrize("unit", ["°C", "K", "N·m", "min⁻¹", "kg·m²", "J/(kg*K)", "W/(m^2*K)", "(K/W)**2", "%", "1"])
def test_the_grammar_lets_engineers_units_through(unit):
    assert units.unit_problem(unit) is None


@pytest.mark.parametrize("unit", NOT_UNITS, ids=range(len(NOT_UNITS)))
@pytest.mark.parametrize("channel", ["T_air", "extra"])
@pytest.mark.parametrize("given", ["title", "--unit"])
def test_a_csv_unit_that_is_no_unit_is_one_line_exit_2(unit, channel, given, tmp_path, short_run, refused):
    csv = tmp_path / "d.csv"
    part = short_run.iloc[:20].drop(columns="time").assign(extra=1.0)
    if given == "title":
        part = part.rename(columns={channel: f"{channel} [{unit}]"})
    part.to_csv(csv, index=False)
    options = ["--unit", f"{channel}={unit}"] if given == "--unit" else []
    if given == "--unit" and channel == "T_air":
        options += ["--unit", "extra=A"]
    elif given == "title" and channel == "T_air":
        options = ["--unit", "extra=A"]
    refused(["import", str(csv), "--out", str(tmp_path / "r.h5"), "--dt", "0.01", *options], str(csv), channel)
    assert not (tmp_path / "r.h5").exists()
