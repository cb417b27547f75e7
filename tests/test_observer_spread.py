"""The plate's band widened by the identification's own doubt (benchlab.observer.spread), scored against /truth on
the reference plant (richer than the model): issue 41. Seeds 21 and 22 were picked before the first run and never
changed; the band's method and constants were set on pipeline runs of other seeds."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from benchlab.identify.api import identify
from benchlab.model.catalog import builtin
from benchlab.model.params import ModelParams
from benchlab.network.simulation import simulate
from benchlab.observer.batch import observe
from benchlab.identify.cooldown import CooldownResult
from benchlab.observer.spread import (FILTER_STD_SUFFIX, discrepancy_spread, model_spread, parameter_draws,
                                     slipping_residual, start_discrepancy, widened)
from benchlab.report.showcase import PLATE, plate_band
from benchlab.runfile import load_run, load_truth
from benchlab.runner.session import RunRequest, execute
from benchlab.wear.clutchfile import default_clutch
from protocols.validation import ValidationConfig, validation_schedule
from sim_bench.bench import SimulatedBench

SENSORS = ["T_flywheel", "T_air", "T_housing"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """(validation run, its truth, parameters identified from a 20 min Table 1 run) on the reference plant."""
    folder = tmp_path_factory.mktemp("spread")
    code, _ = execute(RunRequest("table1", folder / "table1.h5", seed=21, duration_s=1200, install_signals=False,
                                 bench=SimulatedBench()))
    assert code == 0
    result = identify([load_run(folder / "table1.h5")], "nonlinear", starts=2)
    params = ModelParams(builtin("nonlinear"), result.params, result.summary())
    steps = validation_schedule(22, ValidationConfig(segment_s=60.0, table1_cycles=3))
    code, _ = execute(RunRequest("validation", folder / "validation.h5", seed=22, steps=steps, install_signals=False,
                                 bench=SimulatedBench()))
    assert code == 0
    return load_run(folder / "validation.h5"), load_truth(folder / "validation.h5"), params


@pytest.mark.xfail(strict=True, reason="measured: 80 % coverage (target 85 %) with a mean half-width of 69 K: a "
                   "20 min Table 1 run leaves 9 of the 12 parameters not identified, the plate is up to 58 K off, and "
                   "the band covers it only after the first launches (docs/observer.md); pipeline runs (1 h) reach it")
def test_the_widened_band_covers_the_reference_plants_plate(reference):
    run, truth, params = reference
    observed = observe(run, params, SENSORS)
    error = observed.estimate[PLATE].to_numpy() - truth[PLATE].to_numpy()
    assert np.mean(np.abs(error) <= 2 * observed.estimate[PLATE + "_std"].to_numpy()) < 0.85  # the filter alone: not
    band = plate_band(run, truth, widened(observed, model_spread(run, params, [PLATE])), simulate(run, params),
                      params, default_clutch())
    assert band.plate_band_coverage >= 0.85, band
    assert band.half_width_k > band.filter_half_width_k


def test_the_wear_over_the_band_holds_the_truths_plate_wear(reference):
    run, truth, params = reference
    observed = widened(observe(run, params, SENSORS), model_spread(run, params, [PLATE]))
    band = plate_band(run, truth, observed, simulate(run, params), params, default_clutch())
    estimate, low, high = band.wear_mm["plate"]
    assert low < estimate < high  # the band has a width, and the estimate is inside it
    assert band.wear_covered("plate"), band.as_dict()


def test_the_flywheels_wear_band_carries_the_models_miss_on_its_sensor_while_slipping(reference):
    """The flywheel is measured, so its filter band is tight; but its sensor lags the friction face that wears, and
    the filter follows the sensor: the wear is computed over a band widened by the model's miss on that sensor
    while slipping, on this run, which the fit never saw (benchlab.observer.spread)."""
    run, truth, params = reference
    observed = widened(observe(run, params, SENSORS), model_spread(run, params, [PLATE]))
    model = simulate(run, params)
    miss = slipping_residual(run, model, "T_flywheel")
    assert miss > 0.5  # a richer plant than the model: it misses while the clutch slips
    tight = plate_band(run, truth, observed, model, params, default_clutch())
    wide = plate_band(run, truth, observed, model, params, default_clutch(), flywheel_miss_k=miss)
    assert wide.wear_mm["flywheel"][2] - wide.wear_mm["flywheel"][1] > tight.wear_mm["flywheel"][2] - tight.wear_mm["flywheel"][1]
    assert wide.wear_covered("flywheel"), wide.as_dict()


def test_measured_states_keep_the_filters_band_and_the_draws_are_reproducible(reference):
    run, _, params = reference
    observed = observe(run, params, SENSORS)
    spread = model_spread(run, params, [PLATE, "T_flywheel"])
    wide = widened(observed, spread).estimate
    assert "T_flywheel" + FILTER_STD_SUFFIX not in wide  # a sensor reads it: its readings check its band
    np.testing.assert_array_equal(wide["T_flywheel_std"], observed.estimate["T_flywheel_std"])
    assert (wide[PLATE + "_std"] >= observed.estimate[PLATE + "_std"]).all()
    again = parameter_draws(params)
    assert [dict(p) for p in again] == [dict(p) for p in parameter_draws(params)]


def test_the_spread_taken_draw_by_draw_is_the_sample_deviation_of_all_the_draws_together(reference):
    """model_spread never holds the draws' predictions together (Welford's running sums): it must still give their
    sample standard deviation, to rounding."""
    run, _, params = reference
    channels = [PLATE, "T_flywheel"]
    draws = parameter_draws(params, 8)
    together = np.std([simulate(run, p, params.network)[channels].to_numpy() for p in draws], axis=0, ddof=1)
    spread = model_spread(run, params, channels, draws=8)
    assert list(spread.columns) == channels
    assert together.max() > 1.0  # draws that differ: the comparison is not of zeros
    np.testing.assert_allclose(spread.to_numpy(), together, rtol=1e-9, atol=1e-9)


def test_a_parameter_file_without_uncertainty_adds_no_spread(reference):
    run, _, params = reference
    bare = ModelParams(params.definition, dict(params))
    assert parameter_draws(bare) == []
    assert (model_spread(run, bare, [PLATE])[PLATE] == 0).all()


def _cooldown(t_start: float, plate_start_c: float) -> CooldownResult:
    return CooldownResult(0, 1000.0, 1, 0.0, t_start, t_start + 600.0, 0.3, 0.01, 0.02, plate_start_c, 0.5, 0.1,
                          100, 1.0)


def test_the_sweeps_reading_of_the_plate_widens_in_proportion_to_the_models_rise():
    """The cool-downs read the plate 50 % further above ambient than the model puts it, once 30 % nearer: r is
    their RMS; a cool-down that read nothing is left out; σ is r times the model's distance from ambient."""
    time = np.arange(0.0, 4000.0, 10.0)
    model = 20.0 + 60.0 * (1.0 - np.exp(-time / 1500.0))  # the model's plate, ambient 20 °C
    at = {t: float(np.interp(t, time, model)) for t in (500.0, 1500.0, 3000.0)}
    points = [_cooldown(500.0, at[500.0] + 0.5 * (at[500.0] - 20.0)),
              _cooldown(1500.0, at[1500.0] - 0.3 * (at[1500.0] - 20.0)),
              _cooldown(3000.0, float("nan"))]
    relative = start_discrepancy(points, time, model, 20.0)
    assert relative == pytest.approx(np.sqrt((0.5 ** 2 + 0.3 ** 2) / 2), rel=1e-3)
    assert start_discrepancy(points[2:], time, model, 20.0) is None
    sigma = discrepancy_spread(pd.Series(model, name="T_pressure_plate"), 20.0, relative)["T_pressure_plate"]
    assert sigma.iloc[0] == 0.0 and sigma.iloc[-1] == pytest.approx(relative * (model[-1] - 20.0))
