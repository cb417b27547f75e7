"""Run files, parameter files, `simulate` and `import` on the command line, and bad input."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

import benchlab
from benchlab.cli import main
from benchlab.model.params import paper_params
from benchlab.runfile import REQUIRED


def test_round_trip_and_api(run_file, short_run):
    run = benchlab.load_run(run_file)
    assert list(run.columns)[:10] == list(REQUIRED)
    assert run.attrs["dt"] == pytest.approx(0.01)
    assert run.attrs["units"]["T_air"] == "degC"
    np.testing.assert_array_equal(run["T_flywheel"].to_numpy(), short_run["T_flywheel"].to_numpy())


def test_simulate_cli_on_foreign_file(tmp_path, foreign_run, params_file, capsys):
    assert main(["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")]) == 0
    with h5py.File(tmp_path / "s.h5") as f:
        g = f["simulated"]
        assert set(g) == {"time", "T_pressure_plate", "T_flywheel", "T_air", "T_housing"}
        assert all(g[k].attrs["units"] == ("s" if k == "time" else "degC") for k in g)
        assert g["T_flywheel"][99] > g["T_flywheel"][0] + 1.0  # 100 samples of 2 kW each side heated it


def test_import_csv(tmp_path, short_run):
    csv = tmp_path / "d.csv"
    short_run.iloc[:1000].to_csv(csv, index=False)
    assert main(["import", str(csv), "--out", str(tmp_path / "r.h5")]) == 0
    run = benchlab.load_run(tmp_path / "r.h5")
    assert run.attrs["protocol"] == "imported" and len(run) == 1000
    np.testing.assert_allclose(run["T_air"], short_run["T_air"].iloc[:1000])


def _break(path, how):
    with h5py.File(path, "a") as f:
        how(f)


BAD_RUNS = {
    "missing channel": (lambda f: f["aligned"].__delitem__("T_air"), "/aligned/T_air"),
    "missing units": (lambda f: f["aligned/T_housing"].attrs.__delitem__("units"), "/aligned/T_housing.units"),
    "wrong units": (lambda f: f["aligned/engine_speed"].attrs.__setitem__("units", "rad/s"), "/aligned/engine_speed.units"),
    "non-uniform time": (lambda f: f["aligned/time"].__setitem__(5, 0.77), "/aligned/time"),
    "no schema": (lambda f: f.attrs.__delitem__("schema"), "schema"),
}


@pytest.mark.parametrize("case", sorted(BAD_RUNS))
def test_bad_run_file_is_one_line_exit_2(case, run_file, params_file, tmp_path, capsys):
    how, field = BAD_RUNS[case]
    _break(run_file, how)
    code = main(["simulate", str(run_file), "--params", str(params_file), "--out", str(tmp_path / "s.h5")])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and str(run_file) in err and field in err


def test_not_hdf5_and_missing_file(tmp_path, params_file, capsys):
    junk = tmp_path / "junk.h5"
    junk.write_text("not hdf5")
    assert main(["simulate", str(junk), "--params", str(params_file), "--out", str(tmp_path / "s.h5")]) == 2
    assert "HDF5" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "none.h5"), "--params", str(params_file), "--out", "x.h5"]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize("edit,field", [
    (lambda d: d["params"].pop("C_F"), "params.C_F"),
    (lambda d: d["params"].__setitem__("R_AT", -0.1), "params.R_AT"),
    (lambda d: d["params"].__setitem__("C_A", 0), "params.C_A"),
    (lambda d: d.__setitem__("model", "quadratic"), "model"),
])
def test_bad_params_file(edit, field, run_file, params_file, tmp_path, capsys):
    doc = json.loads(params_file.read_text())
    edit(doc)
    params_file.write_text(json.dumps(doc))
    assert main(["simulate", str(run_file), "--params", str(params_file), "--out", str(tmp_path / "s.h5")]) == 2
    err = capsys.readouterr().err
    assert field in err and str(params_file) in err and len(err.strip().splitlines()) == 1


def test_linear_params_file_may_omit_convection_terms(tmp_path):
    path = tmp_path / "lin.json"
    values = {k: v for k, v in paper_params("linear").items() if k not in ("a1", "b1", "a2", "b2")}
    path.write_text(json.dumps({"model": "linear", "params": values}))
    assert benchlab.load_params(path)["a1"] == 0.0


def test_csv_missing_column_and_bad_value(tmp_path, short_run, capsys):
    csv = tmp_path / "d.csv"
    short_run.iloc[:50].drop(columns=["T_housing"]).to_csv(csv, index=False)
    assert main(["import", str(csv), "--out", str(tmp_path / "r.h5")]) == 2
    assert "column T_housing" in capsys.readouterr().err
    frame = short_run.iloc[:50].copy()
    frame["T_air"] = frame["T_air"].astype(object)
    frame.loc[10, "T_air"] = "hot"
    frame.to_csv(csv, index=False)
    assert main(["import", str(csv), "--out", str(tmp_path / "r.h5")]) == 2
    assert "column T_air, line 12" in capsys.readouterr().err


def test_import_refuses_to_overwrite_an_existing_file_without_force(tmp_path, short_run, capsys):
    csv, out = tmp_path / "d.csv", tmp_path / "r.h5"
    short_run.iloc[:100].to_csv(csv, index=False)
    out.write_bytes(b"an earlier run")
    assert main(["import", str(csv), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--force" in err and str(out) in err
    assert out.read_bytes() == b"an earlier run"
    assert main(["import", str(csv), "--out", str(out), "--force"]) == 0
    assert len(benchlab.load_run(out)) == 100


@pytest.mark.parametrize("sep, decimal, flags", [
    (";", ",", []),                                   # a German spreadsheet: found from the header and the data
    (";", ".", []),                                   # semicolons with decimal points
    ("\t", ",", []),
    (";", ",", ["--sep", ";", "--decimal", ","]),     # said on the command line
])
def test_import_reads_semicolon_and_decimal_comma_csv(sep, decimal, flags, tmp_path, short_run):
    csv, out = tmp_path / "d.csv", tmp_path / "r.h5"
    part = short_run.iloc[:300]
    part.to_csv(csv, index=False, sep=sep, decimal=decimal)
    assert main(["import", str(csv), "--out", str(out), *flags]) == 0
    run = benchlab.load_run(out)
    for c in part.columns:
        np.testing.assert_allclose(run[c].to_numpy(), part[c].to_numpy(), rtol=1e-12)


def test_import_reads_units_in_the_header_and_checks_them(tmp_path, short_run, capsys):
    csv, out = tmp_path / "d.csv", tmp_path / "r.h5"
    part = short_run.iloc[:50]
    part.rename(columns={"T_air": "T_air [degC]", "time": "time [s]"}).to_csv(csv, index=False)
    assert main(["import", str(csv), "--out", str(out)]) == 0
    np.testing.assert_allclose(benchlab.load_run(out)["T_air"].to_numpy(), part["T_air"].to_numpy())
    part.rename(columns={"T_air": "T_air [Nm]"}).to_csv(csv, index=False)  # a temperature in N·m
    assert main(["import", str(csv), "--out", str(tmp_path / "k.h5")]) == 2
    err = capsys.readouterr().err
    assert "column T_air [Nm]" in err and "degC" in err and not (tmp_path / "k.h5").exists()
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_simulate_writes_a_run_file_the_other_commands_read(run_file, params_file, tmp_path, capsys):
    sim, again = tmp_path / "sim.h5", tmp_path / "again.h5"
    assert main(["simulate", str(run_file), "--params", str(params_file), "--out", str(sim)]) == 0
    before, after = benchlab.load_run(run_file), benchlab.load_run(sim)  # the contract's reader takes it
    assert list(after.columns) == list(before.columns) and after.attrs["protocol"] == before.attrs["protocol"]
    for c in before.columns:
        np.testing.assert_array_equal(after[c].to_numpy(), before[c].to_numpy())
    fits = []
    for source, out in ((run_file, "p_run.json"), (sim, "p_sim.json")):
        assert main(["identify", str(source), "--model", "linear", "--starts", "1", "--out", str(tmp_path / out)]) == 0
        fits.append(json.loads((tmp_path / out).read_text())["params"])
    assert fits[0] == fits[1]  # the same measurements: the same fit
    assert main(["wear", str(sim), "--params", str(params_file), "--json"]) == 0
    assert main(["simulate", str(sim), "--params", str(params_file), "--out", str(again)]) == 0
    with h5py.File(sim) as a, h5py.File(again) as b:
        assert a.attrs["source_run"] == str(run_file) and b.attrs["source_run"] == str(sim)
        for name in a["simulated"]:
            np.testing.assert_array_equal(a["simulated"][name][()], b["simulated"][name][()])
    assert main(["simulate", str(sim), "--params", str(params_file), "--out", str(sim)]) == 2
    assert "a file other than the run file" in capsys.readouterr().err
    assert benchlab.load_run(sim)["T_air"].equals(after["T_air"])  # refused before anything was written
