"""`benchlab deploy`: the generated C module compiled with the strict flags and run beside benchlab's online observer
on the first minutes of the session's simulated Table 1 run (the paper's clutch, linear, nonlinear, and a clutch
extended the way diagnose extends it). Skipped where the machine has no `cc`; cppcheck where it has none."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from benchlab.cli import main
from benchlab.deploy import verify
from benchlab.deploy.module import prove, write_module
from benchlab.deploy.plan import make_plan
from benchlab.diagnose.library import channel_source, extra_node, sensor_calibration, sensor_lag
from benchlab.model.definition import parse_model
from benchlab.model.params import ModelParams, paper_params, save_params
from benchlab.runfile import write_run
from benchlab.wear.clutchfile import default_clutch

SAMPLES = 12_000  # two minutes at 10 ms: the first heat-up, the estimate converging, wear growing
needs_cc = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) on this machine: the module "
                                                                  "cannot be compiled here")


@pytest.fixture(scope="module")
def part(short_run):
    run = short_run.iloc[:SAMPLES].copy()
    run.attrs = dict(short_run.attrs)
    return run


def extended() -> ModelParams:
    """The nonlinear clutch with diagnose's extensions: a mass hung on the flywheel, a slip-driven heat source into
    the plate (a power law of the clutch speed) and a lagging air sensor that reads 1.5 % + 0.6 K high and drifts
    (the module turns its readings back into temperatures); the new parameters at set values."""
    params = paper_params("nonlinear")
    model = params.definition
    channels = {"clutch_speed": np.array([0.0, 150.0])}
    for build in (extra_node(("F",), "mass_F", "H"), channel_source(("clutch_speed",), "P", (None,)),
                  sensor_lag("T_air", "A"), sensor_calibration("T_air")):
        model = build(model, channels)
    doc = model.to_doc()
    doc["calibrations"][0]["drift"] = "drift_T_air"
    doc["parameters"]["drift_T_air"] = {"start": 2e-4, "min": -1e-2, "max": 1e-2, "unit": "K/s", "scale": 1e-4}
    model = parse_model(doc, "extended.toml")
    values = {**params, **{name: p.start for name, p in model.parameters.items() if name not in params},
              "gain_T_air": 1.015, "offset_T_air": 0.6}
    values.update({name: 40.0 for name in values if name.startswith("q_")})
    return ModelParams(model, values, params.extra)


@needs_cc
@pytest.mark.parametrize("model, real", [("nonlinear", "float"), ("nonlinear", "double"), ("linear", "float"),
                                         ("extended", "float"), ("extended", "double")])
def test_the_module_computes_what_the_observer_computes(part, model, real):
    params = extended() if model == "extended" else paper_params(model)
    plan = make_plan(params, ["T_air"], float(part.attrs["dt"]), default_clutch())
    proof = prove(plan, [part], real)
    worst = max(proof["max_abs_dev_K"].values())
    assert set(proof["max_abs_dev_K"]) >= {"T_pressure_plate", "T_flywheel", "T_air", "T_housing"}
    if real == "float":
        assert worst <= 0.05 and proof["plate_sigma_rel_dev"] <= 0.01 and proof["wear_rel_dev"] <= 0.005, proof
    else:
        assert worst <= 1e-6 and proof["plate_sigma_rel_dev"] <= 1e-6 and proof["wear_rel_dev"] <= 1e-6, proof
    assert proof["runs"][0]["samples"] == SAMPLES


@needs_cc
def test_broken_inputs_are_held_clamped_and_never_reach_the_state(part, tmp_path):
    """A NaN input computes what its held value computes, an absurd one what its clamp computes; a reading that is
    infinite or absurd is no reading; the sensor gone for a minute only widens the band."""
    plan = make_plan(paper_params("nonlinear"), ["T_air"], float(part.attrs["dt"]), default_clutch())
    write_module(tmp_path, plan, "float")
    built = verify.build(tmp_path, plan)
    x0 = verify.reference(plan, part.iloc[:10])["x0"]
    clean = verify.run_module(built, plan, part, x0, "float")
    inputs, _, _ = verify.run_inputs(plan, part)
    raw = inputs.copy()
    column = plan.inputs.index("engine_speed")
    raw[3000:3500, column] = np.nan
    raw[4000:4100, column] = 1e12  # clamped to the top of the range
    held = inputs.copy()
    held[3000:3500, column] = inputs[2999, column]
    held[4000:4100, column] = plan.input_range(column)[1]
    readings = verify.fresh(verify.sensor_readings(part, plan.sensors))
    gone = readings.copy()
    gone[6000:12000] = np.nan
    gone[5000] = np.inf
    gone[5001] = 1e6
    a = verify.run_module(built, plan, part, x0, "float", inputs=raw, readings=gone)
    b = verify.run_module(built, plan, part, x0, "float", inputs=held, readings=np.where(np.isfinite(gone) &
                                                                                          (np.abs(gone) < 600), gone,
                                                                                          np.nan))
    assert np.all(np.isfinite(a["temperature"])) and np.all(np.isfinite(a["std"]))
    np.testing.assert_array_equal(a["temperature"], b["temperature"])
    np.testing.assert_array_equal(a["wear"], b["wear"])
    air = plan.state_channels.index("T_air")
    assert a["std"][11_999, air] > 3 * clean["std"][11_999, air]  # a minute without the sensor: wider band


@needs_cc
def test_deploy_command_writes_the_module_and_its_proof(part, tmp_path, capsys):
    run, params = tmp_path / "run.h5", tmp_path / "p.json"
    write_run(run, part, part.attrs["dt"], protocol="table1")
    save_params(params, paper_params("nonlinear"))
    out = tmp_path / "module"
    assert main(["deploy", str(params), "--out", str(out), "--verify", str(run), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"max_abs_dev_K", "plate_sigma_rel_dev", "wear_rel_dev", "state_bytes", "code_bytes",
            "step_us"} <= set(result)
    assert result["code_bytes"] > 0 and result["state_bytes"] > 0
    assert json.loads((out / "verify.json").read_text())["max_abs_dev_K"] == result["max_abs_dev_K"]
    text = (out / "clutch_nonlinear.c").read_text() + (out / "clutch_nonlinear.h").read_text()
    includes = {line.split()[1] for line in text.splitlines() if line.startswith("#include")}
    assert includes == {"<math.h>", "<stdint.h>", '"clutch_nonlinear.h"'}
    assert not any(word in text for word in ("malloc", "static real state", "static double", "static float"))
    assert "Proof" in (out / "README.md").read_text()


def test_no_compiler_is_one_line(tmp_path, params_file, run_file, monkeypatch, capsys):
    monkeypatch.setattr(shutil, "which", lambda name, *a, **k: None)
    assert main(["deploy", str(params_file), "--out", str(tmp_path / "m"), "--verify", str(run_file)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "C compiler" in err


@pytest.mark.skipif(shutil.which("cppcheck") is None, reason="cppcheck is not installed (Debian's package: .ci/run "
                                                              "installs it where it can)")
def test_cppcheck_finds_nothing(tmp_path):
    plan = make_plan(extended(), ["T_air"], 0.01, default_clutch())
    write_module(tmp_path, plan, "float")
    done = subprocess.run(["cppcheck", "--std=c99", "--enable=warning,portability,performance", "--error-exitcode=1",
                           "--inline-suppr", "--quiet", str(tmp_path / f"{plan.name}.c")], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
