"""A sensor's calibration (`[[calibrations]]`, contract §6): a measured channel reads gain * T + offset + drift * t.
The model file round-trips, the simulation's output stage and identification's residuals read through it, and a fit
recovers a calibration error put on the session's simulated Table 1 run (the run itself, not a new one)."""

from __future__ import annotations

import json
import tomllib
from dataclasses import replace

import numpy as np
import pytest

from benchlab.diagnose.library import calibration_parameters, candidates, sensor_calibration, telling_apart
from benchlab.identify.data import prepare
from benchlab.identify.fit import fit
from benchlab.model.build import build_spec
from benchlab.model.catalog import builtin
from benchlab.model.definition import parse_model, to_toml
from benchlab.model.params import ModelParams, load_params, paper_params, save_params
from benchlab.network.sensors import Calibration, reading, temperature_of
from benchlab.network.simulation import simulate

GAIN, OFFSET, DRIFT = 1.015, 1.2, 2.0e-4  # a PT1000 that reads 1.2 K + 1.5 % high and creeps 0.72 K an hour
CHANNEL = "T_flywheel"


def calibrated(drift: bool = False) -> ModelParams:
    """The paper's nonlinear clutch whose flywheel sensor reads GAIN * F + OFFSET (+ DRIFT * t)."""
    params = paper_params("nonlinear")
    model = sensor_calibration(CHANNEL)(params.definition, {})
    gain, offset = calibration_parameters(CHANNEL)
    values = {**params, gain: GAIN, offset: OFFSET}
    if drift:
        doc = model.to_doc()
        doc["calibrations"][0]["drift"] = "drift_F"
        doc["parameters"]["drift_F"] = {"start": 0.0, "min": -0.01, "max": 0.01, "unit": "K/s", "scale": 1e-4}
        model = parse_model(doc, "drift.toml")
        values["drift_F"] = DRIFT
    return ModelParams(model, values, params.extra)


def misread(run, drift: float = 0.0):
    """The run with its flywheel channel read through the calibration (t from the run's first sample)."""
    out = run.copy()
    out.attrs = dict(run.attrs)
    seconds = np.arange(len(run)) * float(run.attrs["dt"])
    out[CHANNEL] = reading(Calibration("g", "o", "d"), {"g": GAIN, "o": OFFSET, "d": drift}, run[CHANNEL].to_numpy(),
                           seconds)
    return out


def test_old_files_mean_the_same_and_calibrations_round_trip():
    plain = builtin("nonlinear")
    assert plain.calibrations == () and "calibrations" not in plain.to_doc()
    model = calibrated(drift=True).definition
    assert parse_model(tomllib.loads(to_toml(model)), "again.toml") == model
    assert parse_model(json.loads(json.dumps(model.to_doc())), "again.json") == model
    assert model.calibrations[0].names == ("gain_T_flywheel", "offset_T_flywheel", "drift_F")


def test_the_parameter_file_carries_the_calibration_with_its_units(tmp_path):
    save_params(tmp_path / "p.json", calibrated(drift=True))
    params = load_params(tmp_path / "p.json")
    assert params.definition == calibrated(drift=True).definition and params["drift_F"] == DRIFT
    units = json.loads((tmp_path / "p.json").read_text())["units"]
    assert (units["gain_T_flywheel"], units["offset_T_flywheel"], units["drift_F"]) == ("1", "K", "K/s")


def test_the_inverse_is_the_inverse():
    calibration = Calibration("g", "o", "d")
    values = {"g": GAIN, "o": OFFSET, "d": DRIFT}
    t = np.array([0.0, 10.0, 3600.0])
    temperature = np.array([20.0, 55.5, 140.0])
    np.testing.assert_allclose(temperature_of(calibration, values, reading(calibration, values, temperature, t), t),
                               temperature, rtol=1e-14)


@pytest.mark.parametrize("drift", [False, True])
def test_simulated_outputs_read_through_the_calibration(short_run, drift):
    """A calibrated model on the misread run is the plain model on the true run, read through the calibration:
    states start from what the first reading stands for, and only the calibrated channel changes."""
    params = calibrated(drift)
    plain = simulate(short_run, paper_params("nonlinear"))
    seen = simulate(misread(short_run, DRIFT if drift else 0.0), params)
    seconds = np.arange(len(short_run)) * float(short_run.attrs["dt"])
    expected = GAIN * plain[CHANNEL].to_numpy() + OFFSET + (DRIFT * seconds if drift else 0.0)
    np.testing.assert_allclose(seen[CHANNEL].to_numpy(), expected, rtol=0, atol=1e-9)
    others = [c for c in plain.columns if c != CHANNEL]
    np.testing.assert_allclose(seen[others].to_numpy(), plain[others].to_numpy(), rtol=0, atol=1e-9)


def test_identification_recovers_the_calibration(short_run):
    """Offset and gain fitted (K, 1) with the physics held at the paper's values, on the run and on the misread run:
    the second is the first read through the calibration put on the run (whatever the paper's values leave over,
    which the first absorbs, the second absorbs read through it)."""
    params = calibrated()
    gain, offset = calibration_parameters(CHANNEL)
    model = params.definition.with_fixed({k: v for k, v in paper_params("nonlinear").items()
                                          if k in params.definition.parameters})
    spec = build_spec(model)
    assert [(p.name, p.unit) for p in spec.free] == [(gain, "1"), (offset, "K")]
    own = fit(spec, [prepare(short_run, 1.0)]).params
    result = fit(spec, [prepare(misread(short_run), 1.0)]).params
    assert result[gain] == pytest.approx(GAIN * own[gain], rel=1e-3)
    assert result[offset] == pytest.approx(GAIN * own[offset] + OFFSET, abs=0.05)
    assert abs(result[offset] - own[offset]) > 1.0  # the calibration moved it: the comparison has content


def test_every_measured_output_gets_a_calibration_candidate_named_as_a_sensor():
    model = builtin("nonlinear")
    channels = {name: np.array([0.0, 1.0]) for name in ("friction_power", "engine_speed", *model.outputs)}
    found = {c.key: c for c in candidates(model, channels) if c.key.startswith("sensor_calibration_")}
    assert set(found) == {f"sensor_calibration_{c}" for c in model.outputs}
    flywheel = found["sensor_calibration_T_flywheel"]
    assert flywheel.mechanism == "sensor" and "sensor error" in flywheel.summary
    assert "known-temperature soak" in flywheel.summary and "second sensor on the flywheel" in flywheel.summary
    physics = next(c for c in candidates(model, channels) if c.mechanism == "heat_source")
    assert telling_apart(model, physics, flywheel).startswith("a known-temperature soak of the T_flywheel sensor")
    extended = flywheel.build(model, channels)
    assert extended.calibrations[0].output == "T_flywheel"
    assert {extended.parameters[n].unit for n in extended.calibrations[0].names} == {"1", "K"}
    drifts = {c.key: c for c in candidates(model, channels) if c.key.startswith("sensor_drift_")}
    assert set(drifts) == {f"sensor_drift_{c}" for c in model.outputs}
    both = drifts["sensor_drift_T_flywheel"].build(extended, channels)  # found after the offset: one entry
    assert [(c.output, c.names) for c in both.calibrations] == [
        ("T_flywheel", ("gain_T_flywheel", "offset_T_flywheel", "drift_T_flywheel"))]
    assert both.parameters["drift_T_flywheel"].unit == "K/s"
    left = {c.key for c in candidates(both, channels) if c.mechanism == "sensor" and c.signal == "T_flywheel"}
    assert left == {"sensor_lag"}  # a calibrated, drifting sensor gets neither again, only the clutch's named lag


def test_the_plants_miscalibrated_sensor_reads_through_its_calibration():
    """sim_bench's hidden calibration error acts where the plant's readings are made, on its channel only."""
    from sim_bench import plant as P

    plant = P.ThermalPlant(effects=[P.sensor_calibration("T_housing", -0.8, 1.02, 1e-4)])
    states = {name: np.array([30.0, 60.0]) for name in plant.state_names}
    seen = plant.sensor_temperatures(states, np.array([0.0, 100.0]))
    np.testing.assert_allclose(seen["T_housing"], [1.02 * 30.0 - 0.8, 1.02 * 60.0 - 0.8 + 0.01], rtol=1e-12)
    assert seen["T_air"] is states["A"] and seen["T_flywheel_1"] is states["F"]


def test_the_observer_reads_a_calibrated_sensor_as_the_temperature_it_stands_for(short_run):
    """Observing the misread run with the calibrated model is observing the true run with the plain one: each
    reading turned back into its temperature, its noise divided by the gain (the filter's states the same). Without
    drift: a drift put on the grid's held values would make every held sample a fresh reading."""
    from benchlab.observer.batch import observe

    part = short_run.iloc[:30_000].copy()
    part.attrs = dict(short_run.attrs)
    misread_part = misread(part)
    plain = observe(part, paper_params("nonlinear"), [CHANNEL, "T_air"], paper_params("nonlinear").network)
    params = calibrated()
    noise = plain.model.noise  # the misread readings' noise is GAIN times the true ones' (a reading's noise, in K)
    noise = replace(noise, sensor_k={**noise.sensor_k, CHANNEL: GAIN * noise.sensor_k[CHANNEL]})
    seen = observe(misread_part, params, [CHANNEL, "T_air"], params.network, noise=noise)
    np.testing.assert_allclose(seen.estimate["T_pressure_plate"], plain.estimate["T_pressure_plate"], atol=1e-6)
    np.testing.assert_allclose(seen.estimate[CHANNEL], plain.estimate[CHANNEL], atol=1e-6)


def test_wear_takes_the_nodes_temperatures_not_the_miscalibrated_readings(short_run):
    from benchlab.wear.thermal import lining_temperatures

    plain = lining_temperatures(short_run, paper_params("nonlinear"), 0.5)
    seen = lining_temperatures(misread(short_run), calibrated(), 0.5)
    np.testing.assert_allclose(seen[CHANNEL].to_numpy(), plain[CHANNEL].to_numpy(), rtol=0, atol=1e-9)
