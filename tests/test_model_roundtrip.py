"""`diagnose --save-model` writes the extended model it found as a model file every command takes: identify
re-fits it to the same values, and simulate, report and wear run from the parameter file that carries it."""

from __future__ import annotations

import contextlib
import io
import json

import h5py
import numpy as np
import pytest

from benchlab.cli import main
from benchlab.model.definition import load_model
from benchlab.model.params import load_params, paper_params
from benchlab.runfile import write_run
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

SPLIT = 0.62  # the plate's share of the friction power on the simulated bench; the model files say 0.5


def _cli(argv: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(argv)
    return code, out.getvalue()


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A 1 h run of a clutch whose heat split is not half and half, diagnosed from the nonlinear model file."""
    d = tmp_path_factory.mktemp("roundtrip")
    plant = P.ThermalPlant(paper_params("nonlinear"), [P.heat_split(SPLIT)])
    run = run_schedule(table1_schedule(103, duration_s=3600.0), plant, seed=103)
    write_run(d / "run.h5", run, run.attrs["dt"], protocol="table1")
    code, out = _cli(["diagnose", str(d / "run.h5"), "--model", "nonlinear", "--json",
                      "--save-model", str(d / "best.toml")])
    assert code == 0
    return d, json.loads(out)


def test_saved_model_is_the_best_model_with_its_fitted_values_as_starts(saved):
    d, result = saved
    model = load_model(d / "best.toml")
    assert [f["candidate"] for f in result["findings"]] == ["heat_split"]
    assert model.name == result["best"]["model"] == "nonlinear+heat_split"
    assert result["best"]["model_file"] == str(d / "best.toml")
    best = result["best"]["params"]
    assert {p.name: p.start for p in model.free_parameters()} == pytest.approx({k: best[k] for k in model.parameters})
    assert {s.name: s.heat.text for s in model.sources} == {
        "plate share": "(0.5*friction_power) + (split - 0.5) * friction_power",
        "flywheel share": "(0.5*friction_power) - (split - 0.5) * friction_power"}
    assert model.parameters["split"].start == pytest.approx(SPLIT, abs=0.03)


@pytest.fixture(scope="module")
def refit(saved):
    """`identify --model best.toml` at diagnose's fitting step, from the saved starts alone."""
    d, _ = saved
    code, out = _cli(["identify", str(d / "run.h5"), "--model", str(d / "best.toml"), "--starts", "1",
                      "--step", "1", "--out", str(d / "best.json")])
    assert code == 0
    return out


def test_identify_refits_the_saved_model_to_the_same_values(saved, refit):
    d, result = saved
    assert "nonlinear+heat_split model" in refit
    doc = json.loads((d / "best.json").read_text())
    assert doc["model"] == "nonlinear+heat_split" and doc["network"] == load_model(d / "best.toml").to_doc()
    best = result["best"]["params"]
    refit = doc["params"]
    for name in load_model(d / "best.toml").parameters:  # the same optimum (measured: within 0.13 %); identify fits
        assert refit[name] == pytest.approx(best[name], rel=0.01), name  # every start temperature, diagnose ϑ_F's


def test_simulate_report_and_wear_take_the_parameter_file_with_the_network(saved, refit, tmp_path):
    d, _ = saved
    params = load_params(d / "best.json")
    assert params.model == "nonlinear+heat_split" and params["split"] == pytest.approx(SPLIT, abs=0.03)
    code, _ = _cli(["simulate", str(d / "run.h5"), "--params", str(d / "best.json"), "--out", str(tmp_path / "s.h5")])
    assert code == 0
    with h5py.File(tmp_path / "s.h5") as f:
        assert set(f["simulated"]) == {"time", "T_pressure_plate", "T_flywheel", "T_air", "T_housing"}
        plate = f["simulated/T_pressure_plate"][()]
    assert np.max(plate) > 60.0  # the plate gets 62 % of the heat
    code, out = _cli(["wear", str(d / "run.h5"), "--params", str(d / "best.json"), "--json"])
    assert code == 0 and json.loads(out)["split"] == pytest.approx(params["split"])
    code, _ = _cli(["report", str(d / "run.h5"), "--params", str(d / "best.json"), "--out", str(tmp_path / "report")])
    assert code == 0 and (tmp_path / "report" / "report.md").exists()
    code, _ = _cli(["simulate", str(d / "run.h5"), "--params", str(d / "best.json"), "--model", str(d / "best.toml"),
                    "--out", str(tmp_path / "s2.h5")])
    assert code == 0
