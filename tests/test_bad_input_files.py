"""Bad input files (issue 30): damaged HDF5, a directory where a file is expected, documents nested too deeply, model
laws that divide by zero or overflow on the run's data, a CSV a hundred thousand columns wide, and tampered `--resume`
files. Each is one line naming the file and the field, exit 2, no traceback, before anything is allocated or moved."""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import pytest

from benchlab.bounds import MAX_CSV_COLUMNS, MAX_GRID_STEP_S, MAX_RESUMES
from benchlab.model.catalog import BUILTIN
from test_resume_checks import aborted_run  # noqa: F401 - the fixture: a run aborted in cycle 0, resumable



def _damaged(source: Path, out: Path, how: str) -> Path:
    data = bytearray(source.read_bytes())
    if how == "truncated":
        data = data[:len(data) // 2]
    else:  # object headers overwritten: the file opens, a group or dataset does not
        data[200:1200] = bytes(1000)
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("how", ["truncated", "zeroed"])
@pytest.mark.parametrize("command", ["simulate", "identify", "wear", "export", "cooldown", "diagnose", "observe"])
def test_a_damaged_run_file_is_named_as_such(command, how, foreign_run, params_file, tmp_path, refused):
    bad = _damaged(foreign_run, tmp_path / "bad.h5", how)
    argv = {"simulate": ["simulate", str(bad), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
            "identify": ["identify", str(bad), "--out", str(tmp_path / "fit.json")],
            "wear": ["wear", str(bad), "--params", str(params_file)],
            "export": ["export", str(bad), "--to", str(tmp_path / "e.csv")],
            "cooldown": ["cooldown", str(bad), "--params", str(params_file)],
            "diagnose": ["diagnose", str(bad)],
            "observe": ["observe", str(bad), "--params", str(params_file), "--out", str(tmp_path / "o.h5")]}[command]
    err = refused(argv, str(bad), "file")
    assert "HDF5" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.h5", "f.h5", "p.json"]  # nothing written


@pytest.mark.parametrize("case", ["run file", "params", "model", "clutch", "csv", "bench", "export", "watch", "resume",
                                  "compare", "sweep"])
def test_a_directory_where_a_file_is_expected(case, foreign_run, params_file, tmp_path, refused):
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    run, params, out = str(foreign_run), str(params_file), str(tmp_path / "out.h5")
    argv = {"run file": ["simulate", str(folder), "--params", params, "--out", out],
            "params": ["simulate", run, "--params", str(folder), "--out", out],
            "model": ["simulate", run, "--params", params, "--model", str(folder), "--out", out],
            "clutch": ["wear", run, "--params", params, "--clutch", str(folder)],
            "csv": ["import", str(folder), "--out", out],
            "bench": ["run", "table1", "--bench", str(folder), "--cycles", "1", "--out", out],
            "export": ["export", str(folder), "--to", str(tmp_path / "e.csv")],
            "watch": ["watch", str(folder), "--port", "0"],
            "resume": ["run", "--resume", str(folder), "--bench", "sim"],
            "compare": ["report", run, "--params", params, "--compare", str(folder), "--out", str(tmp_path / "r")],
            "sweep": ["report", run, "--params", params, "--sweep", str(folder), "--out", str(tmp_path / "r")]}[case]
    refused(argv, str(folder))
    assert not Path(out).exists()


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


@pytest.mark.parametrize("case", ["params", "params value", "model", "clutch", "bench"])
def test_a_document_nested_too_deeply_is_refused(case, foreign_run, params_file, tmp_path, refused):
    doc = tmp_path / ("doc.json" if case.startswith("params") else "doc.toml")
    if case == "params":
        doc.write_text(_nested(100_000))
    elif case == "params value":
        doc.write_text('{"model": "linear", "params": ' + _nested(5_000) + "}")
    else:
        doc.write_text("x = " + _nested(100_000) + "\n")
    argv = {"params": ["simulate", str(foreign_run), "--params", str(doc), "--out", str(tmp_path / "s.h5")],
            "params value": ["simulate", str(foreign_run), "--params", str(doc), "--out", str(tmp_path / "s.h5")],
            "model": ["simulate", str(foreign_run), "--params", str(params_file), "--model", str(doc), "--out",
                      str(tmp_path / "s.h5")],
            "clutch": ["wear", str(foreign_run), "--params", str(params_file), "--clutch", str(doc)],
            "bench": ["run", "table1", "--bench", str(doc), "--out", str(tmp_path / "r.h5"), "--dry-run"]}[case]
    refused(argv, str(doc), "file", "nested too deeply")


@pytest.mark.parametrize("law, shown", [
    ("R_AT/(engine_speed - engine_speed)", "got inf"),        # a division by zero on every sample
    ("R_AT/0", "got inf"),                                     # a constant one
    ("R_AT*exp(engine_speed*1000)", "got inf"),                # an overflow
    ("R_AT*(engine_speed - 1e6)", "got -"),                    # negative: heat flowing uphill
    ("log(R_AT - R_AT)", "got -inf"),
    ("sqrt(-R_AT)", "got nan"),
    ("R_AT*exp(exp(exp(exp(exp(engine_speed)))))", "got inf"),  # nested calls
])
@pytest.mark.parametrize("command", ["identify", "simulate"])
def test_a_law_the_solver_cannot_use_is_refused_where_the_model_is_checked(law, shown, command, foreign_run,
                                                                          params_file, tmp_path, refused):
    model = tmp_path / "m.toml"
    text = BUILTIN["linear"].read_text()
    assert text.count('resistance = "R_AT"') == 1
    model.write_text(text.replace('resistance = "R_AT"', f'resistance = "{law}"'))
    argv = {"identify": ["identify", str(foreign_run), "--model", str(model), "--starts", "1", "--out",
                         str(tmp_path / "fit.json")],
            "simulate": ["simulate", str(foreign_run), "--params", str(params_file), "--model", str(model), "--out",
                         str(tmp_path / "s.h5")]}[command]
    err = refused(argv, str(model), "links[R_AT].resistance", "positive finite", shown)
    assert "RuntimeWarning" not in err and not (tmp_path / "fit.json").exists()


@pytest.mark.parametrize("command", ["simulate", "wear", "observe", "report"])
def test_a_parameter_file_whose_values_overflow_a_law_is_refused(command, foreign_run, params_file, tmp_path, refused):
    """b1 = 100 1/rpm: exp(b1·ω_e) overflows at any engine speed (it used to end in exit 1 and a RuntimeWarning)."""
    doc = json.loads(params_file.read_text())
    doc["params"]["b1"] = 100.0
    bad = tmp_path / "overflow.json"
    bad.write_text(json.dumps(doc))
    argv = {"simulate": ["simulate", str(foreign_run), "--params", str(bad), "--out", str(tmp_path / "s.h5")],
            "wear": ["wear", str(foreign_run), "--params", str(bad)],
            "observe": ["observe", str(foreign_run), "--params", str(bad), "--out", str(tmp_path / "o.h5")],
            "report": ["report", str(foreign_run), "--params", str(bad), "--out", str(tmp_path / "r")]}[command]
    refused(argv, str(bad), "links[R_PA].resistance", "got inf")
    assert not any(p.suffix in (".h5", ".png") and p.name != "f.h5" for p in tmp_path.rglob("*"))


def test_a_heat_flow_that_overflows_is_refused(foreign_run, tmp_path, refused):
    model = tmp_path / "m.toml"
    text = BUILTIN["linear"].read_text()
    assert text.count('heat = "0.5*friction_power"') >= 1
    model.write_text(text.replace('heat = "0.5*friction_power"', 'heat = "exp(friction_power)"', 1))
    refused(["identify", str(foreign_run), "--model", str(model), "--out", str(tmp_path / "fit.json")],
             str(model), "].heat", "a finite heat flow")


def test_a_csv_wider_than_the_bound_is_refused_at_its_header(tmp_path, refused):
    """100 000 columns used to take 104 s to refuse: the header line alone is counted now."""
    csv = tmp_path / "wide.csv"
    csv.write_text(",".join(f"c{i}" for i in range(100_000)) + "\n" + ",".join("1" for _ in range(100_000)) + "\n")
    refused(["import", str(csv), "--out", str(tmp_path / "r.h5")], str(csv), "header",
             f"at most {MAX_CSV_COLUMNS} columns", "got 100000")
    assert not (tmp_path / "r.h5").exists()


# -- tampered --resume files: sizes and steps checked against benchlab.bounds before the bench is opened ----------

def _progress(field: str, value: float) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        ds = f["acquire/progress"]
        values = ds[()]
        values[json.loads(ds.attrs["fields"]).index(field)] = value
        ds[...] = values
    return edit


def _attr(where: str, name: str, value: object) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        f[where].attrs[name] = value
    return edit


TAMPERED = {  # case: (edit, field named, expected words)
    "dt 0": (_attr("aligned", "dt", 0.0), "/aligned.dt", "a positive time step"),
    "dt 1e6": (_attr("aligned", "dt", 1e6), "/aligned.dt", f"at most {MAX_GRID_STEP_S:g} s"),
    "dt -0.01": (_attr("aligned", "dt", -0.01), "/aligned.dt", "a positive time step"),
    "rows 1e15": (_progress("aligned_rows", 1e15), "aligned_rows", "a whole number of rows"),
    "rows -1": (_progress("aligned_rows", -1.0), "aligned_rows", "a whole number of rows"),
    "rows 1.5": (_progress("aligned_rows", 1.5), "aligned_rows", "a whole number of rows"),
    "rows nan": (_progress("aligned_rows", float("nan")), "aligned_rows", "a whole number of rows"),
    "resumes -3": (_progress("state/resumes", -3.0), "state/resumes", f"[0, {MAX_RESUMES}]"),
    "resumes 1e12": (_progress("state/resumes", 1e12), "state/resumes", f"[0, {MAX_RESUMES}]"),
    "resumes inf": (_progress("state/resumes", float("inf")), "state/resumes", "a whole number"),
    "cycle 1e9": (_progress("state/cycle", 1e9), "state/cycle", "a whole number"),
    "cycle -7": (_progress("state/cycle", -7.0), "state/cycle", "a whole number"),
    "seed abc": (_attr("/", "seed", "abc"), "seed", "a whole number >= 0, got 'abc'"),
    "seed -1": (_attr("/", "seed", -1), "seed", "a whole number >= 0"),
    "options garbage": (_attr("/", "protocol_options", "{{not json"), "protocol_options", "a JSON object"),
    "options list": (_attr("/", "protocol_options", "[1, 2]"), "protocol_options", "a JSON object"),
    "options deep": (_attr("/", "protocol_options", _nested(50_000)), "protocol_options", "a JSON object"),
}


@pytest.mark.parametrize("case", sorted(TAMPERED))
def test_a_tampered_resume_file_is_exit_2_and_the_bench_never_moves(case, aborted_run, tmp_path, refused,
                                                                    opened_benches):
    edit, field, expected = TAMPERED[case]
    out = tmp_path / "run.h5"
    shutil.copy(aborted_run, out)
    shutil.copy(aborted_run.with_suffix(".blf"), out.with_suffix(".blf"))
    with h5py.File(out, "r+") as f:
        edit(f)
    before = hashlib.sha256(out.read_bytes()).hexdigest()
    refused(["run", "--resume", str(out), "--bench", "sim", "--quiet"], f"{out}: ", field, expected)
    assert opened_benches == []
    assert hashlib.sha256(out.read_bytes()).hexdigest() == before and not out.with_suffix(".resume1.blf").exists()


def _rewrite(path: Path, name: str, values) -> None:
    with h5py.File(path, "a") as f:
        units = f["aligned"][name].attrs["units"]
        del f["aligned"][name]
        f["aligned"].create_dataset(name, data=values).attrs["units"] = units


@pytest.mark.parametrize("case, field, expected", [
    ("negative friction power", "/aligned/friction_power", "values in [0, "),
    ("time stamps of 1e15 s", "/aligned/time", "time stamps within"),
    ("dt of 1e9 s", "/aligned/time", "time stamps within"),
])
def test_absurd_values_in_a_run_file_are_refused(case, field, expected, foreign_run, params_file, tmp_path, refused):
    """Values that used to be accepted silently: heat drawn out of the clutch by friction, a grid in geological
    time (where float64 no longer resolves the step and the uniform-grid check passes anything)."""
    import numpy as np

    with h5py.File(foreign_run) as f:
        time = f["aligned/time"][()].astype(np.float64)
    if case == "negative friction power":
        _rewrite(foreign_run, "friction_power", np.full(len(time), -5000.0))
    elif case == "time stamps of 1e15 s":
        _rewrite(foreign_run, "time", time + 1e15)
    else:
        _rewrite(foreign_run, "time", np.arange(len(time)) * 1e9)
        with h5py.File(foreign_run, "a") as f:
            f["aligned"].attrs["dt"] = 1e9
    refused(["simulate", str(foreign_run), "--params", str(params_file), "--out", str(tmp_path / "s.h5")],
            str(foreign_run), field, expected)


def test_an_imported_csv_in_geological_time_is_refused(run_file, tmp_path, refused):
    from benchlab.runfile import load_run

    frame = load_run(run_file).iloc[:50]
    frame["time"] += 1e15
    csv = tmp_path / "d.csv"
    frame.to_csv(csv, index=False)
    refused(["import", str(csv), "--out", str(tmp_path / "r.h5")], str(csv), "column time", "time stamps within")
