"""cooldown-sweep on the simulated bench recovers the plant's true convection resistance at each grid point."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

from benchlab.model.clutch import convection_resistance
from benchlab.identify.cooldown import COVERAGE_K, SYSTEMATIC_REL, CooldownResult, analyse, segments, store, stored
from benchlab.errors import InputError
from benchlab.runner.session import RunRequest, execute
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant

GRID = "800:1,2500:1,1200:0"


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "sweep.h5"
    plant = ThermalPlant()  # the paper's nonlinear clutch
    code, summary = execute(RunRequest("cooldown-sweep", out, seed=2, grid=GRID, bench=SimulatedBench(plant),
                                       install_signals=False))
    assert code == 0 and summary.cycles_done == 3
    return out, plant


def test_sweep_recovers_true_convection_resistance_within_uncertainty(sweep):
    out, plant = sweep
    with h5py.File(out, "r") as f:
        truth = json.loads(f.attrs["sim_truth"])["params"]
        kinds = [k.decode() for k in f["events/kind"][:]]
    assert kinds.count("cooldown_end") == 3 and "timeout" not in kinds
    # parameters other than R as an identification would give them: here the bench's own
    results = analyse(out, truth)
    assert [(r.engine_speed, r.clutch_state) for r in results] == [(800, 1), (2500, 1), (1200, 0)]
    for r in results:
        true_r = float(np.ravel(convection_resistance(plant.params, {"engine_speed": np.array([r.engine_speed]),
                                                                      "clutch_state": np.array([float(r.clutch_state)])}))[0])
        assert r.R_true == pytest.approx(true_r)
        assert r.R_u == pytest.approx(COVERAGE_K * np.hypot(r.R_se, SYSTEMATIC_REL * r.R))
        assert abs(r.R - true_r) <= r.R_u, (r, true_r)
        assert r.R_u < 0.02 * true_r  # and the uncertainty is informative
        assert 0.5 < r.chi2_red < 2.0
    store(out, results, None, "sim-truth")
    with h5py.File(out, "r") as f:
        table = f["analysis/cooldowns"]
        assert table["R"].attrs["units"] == "K/W" and len(table["R"]) == 3


def test_heating_reaches_a_steady_70(sweep):
    out, _ = sweep
    with h5py.File(out, "r") as f:
        ev = [(float(t), k.decode(), d.decode()) for t, k, d in zip(f["events/time"][:], f["events/kind"][:],
                                                                      f["events/detail"][:])]
        t = f["aligned/time"][:]
        tf = f["aligned/T_flywheel"][:]
    ends = [t_end for t_end, kind, detail in ev if kind == "step_end" and detail == "heat: condition"]
    assert len(ends) == 3
    for t_end in ends:
        window = (t > t_end - 120) & (t <= t_end)
        assert abs(np.nanmean(tf[window]) - 70.0) <= 1.0


def test_operating_points_come_from_the_stored_schedule_not_the_event_text(sweep, tmp_path):
    out, _ = sweep
    copy = tmp_path / "sweep.h5"
    shutil.copy(out, copy)
    with h5py.File(copy, "r+") as f:  # every event's text gone: no point left to read from it
        f["events/detail"][...] = b"condition"
    points = [(p["engine_speed"], p["clutch_state"], p["slip_speed"]) for *_, p in segments(copy)]
    assert points == [(800.0, 1.0, 0.0), (2500.0, 1.0, 0.0), (1200.0, 0.0, 1200.0)]
    with h5py.File(copy, "r+") as f:  # a schedule without its cool-down steps cannot place the cool-downs
        rows = json.loads(f["schedule"].attrs["steps_json"])
        f["schedule"].attrs["steps_json"] = json.dumps([{**r, "label": ""} for r in rows])
    with pytest.raises(InputError) as exc:
        segments(copy)
    assert exc.value.field == "/schedule" and "cycle 0" in str(exc.value)


def test_cool_downs_count_by_their_end_reason_not_their_text_in_new_and_old_files(sweep, tmp_path):
    out, _ = sweep
    found = segments(out)
    assert [(cycle, point["engine_speed"]) for cycle, _, _, point in found] == [(0, 800.0), (1, 2500.0), (2, 1200.0)]
    assert all(t0 < t1 for _, t0, t1, _ in found)
    with h5py.File(out, "r") as f:
        ends = [i for i, k in enumerate(f["events/kind"][:]) if k == b"cooldown_end"]
        assert f["events/reason"][ends].tolist() == [b"condition"] * 3
    reworded, old = tmp_path / "reworded.h5", tmp_path / "old.h5"
    shutil.copy(out, reworded)
    shutil.copy(out, old)
    with h5py.File(reworded, "r+") as f:  # the text for people reworded: the same cool-downs
        f["events/detail"][...] = b"ended on time; reworded"
    assert segments(reworded) == found
    with h5py.File(old, "r+") as f:  # written before `reason`: read from the text of then
        del f["events/reason"]
    assert segments(old) == found
    with h5py.File(reworded, "r+") as f:  # a cool-down that ended on time is not fitted
        f["events/reason"][ends[1]] = b"time"
    with h5py.File(old, "r+") as f:
        f["events/detail"][ends[1]] = b"time; engine_speed=2500"
    assert segments(reworded) == segments(old) == [found[0], found[2]]


def test_stored_analysis_reads_back_as_written(sweep, tmp_path):
    out, _ = sweep
    copy = tmp_path / "sweep.h5"
    shutil.copy(out, copy)
    with h5py.File(copy, "r+") as f:  # as the run left it (the first test may have stored its analysis)
        if "analysis" in f:
            del f["analysis"]
    assert stored(copy) is None  # not analysed yet
    rows = [CooldownResult(0, 800.0, 1, 0.0, 100.0, 700.0, 0.1234, 0.001, 0.0025, 75.0, 0.5, 0.04, 600, 1.1, 0.12),
            CooldownResult(2, 1200.0, 0, 1200.0, 1500.0, 2100.0, 0.2345, 0.002, 0.004, 74.0, 0.6, 0.05, 611, 0.9, 0.2)]
    eq11 = {"a1": 0.35, "a1_se": 0.01, "b1": -0.001, "b1_se": 1e-4, "chi2_red": 1.2, "points": 2}
    store(copy, rows, eq11, "p.json")
    back = stored(copy)
    assert back.results == rows and back.eq11 == eq11 and back.params_source == "p.json"
    with h5py.File(copy, "r+") as f:
        assert f["analysis/eq11/b1"].attrs["units"] == "1/rpm" and f["analysis/cooldowns/T_P0"].attrs["units"] == "degC"
        del f["analysis/cooldowns/R"]
    with pytest.raises(InputError) as exc:
        stored(copy)
    assert exc.value.field == "/analysis/cooldowns/R"


def test_cooldown_out_writes_the_analysis_beside_the_run_and_report_reads_it(sweep, tmp_path, capsys):
    """`benchlab cooldown RUN --out A.h5`: the run file keeps its bytes, A.h5 holds /analysis with its source, and
    `report --sweep A.h5` takes it as it takes a run's /analysis (issue 30: analyses never write into a run)."""
    from benchlab.cli import main
    from benchlab.commands.report import sweep_file

    out, _ = sweep
    before = out.read_bytes()
    analysis = tmp_path / "analysis.h5"
    assert main(["cooldown", str(out), "--params", "sim-truth", "--out", str(analysis)]) == 0
    assert out.read_bytes() == before
    back = stored(analysis)
    assert back is not None and len(back.results) >= 3 and back.params_source == "sim-truth"
    with h5py.File(analysis) as f:
        assert f.attrs["source_run"] == str(out) and "aligned" not in f and "schema" not in f.attrs
    sweep_file(str(analysis))  # accepted by report --sweep without /aligned
    assert main(["cooldown", str(out), "--params", "sim-truth", "--out", str(analysis)]) == 2  # exists: --force
    assert "--force" in capsys.readouterr().err


def test_a_sweep_read_by_miscalibrated_sensors_through_a_model_that_says_so(tmp_path):
    """The flywheel and air sensors read 1.2 K + 1.5 % high and 0.8 K low: analysed with a model file whose
    [[calibrations]] say so (contract §6), each cool-down's resistance is the plant's true one again."""
    from dataclasses import replace

    from benchlab.diagnose.library import calibration_parameters, sensor_calibration
    from benchlab.model.params import ModelParams, paper_params
    from sim_bench import plant as P

    out = tmp_path / "sweep.h5"
    errors = {"T_flywheel": (1.2, 1.015), "T_air": (-0.8, 1.0)}
    plant = ThermalPlant(effects=[P.sensor_calibration(c, offset, gain) for c, (offset, gain) in errors.items()])
    code, _ = execute(RunRequest("cooldown-sweep", out, seed=3, grid="1500:1", bench=SimulatedBench(plant),
                                 install_signals=False))
    assert code == 0
    params = paper_params("nonlinear")
    model, values = params.definition, dict(params)
    for channel, (offset, gain) in errors.items():
        model = sensor_calibration(channel)(model, {})
        values.update(zip(calibration_parameters(channel), (gain, offset)))
    (result,) = analyse(out, ModelParams(model, values, params.extra), model=model)
    unaware_model = replace(params.definition, alias=None)  # the same structure without [[calibrations]]
    (unaware,) = analyse(out, params, model=unaware_model)
    true_r = float(np.ravel(convection_resistance(plant.params, {"engine_speed": np.array([1500.0]),
                                                                 "clutch_state": np.array([1.0])}))[0])
    assert abs(result.R - true_r) <= result.R_u and 0.5 < result.chi2_red < 2.0, (result, true_r)
    assert abs(unaware.R - true_r) > 3 * unaware.R_u  # the calibration errors matter: the comparison has content
