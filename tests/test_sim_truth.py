"""The simulated bench records its truth: /truth holds the plant's true temperatures on the run's grid, with units,
for a run closed normally, one aborted by an interlock, and one resumed after that."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from benchlab.runfile import load_run, load_truth
from benchlab.runner.session import RunRequest, execute
from protocols.limits import BenchLimits
from protocols.schedule import Step
from sim_bench import unseen as U
from sim_bench.bench import SimulatedBench
from sim_bench.faults import Fault
from sim_bench.plant import ThermalPlant
from sim_bench.reference_plant import plant_named

STEPS = (Step("open", 40.0, 2000.0, 0.0, 0.0, 0), Step("launch", 10.0, 2000.0, 60.0, 100.0, 1),
         Step("drive", 30.0, 2000.0, 60.0, 100.0, 1), Step("open", 30.0, 1500.0, 0.0, 100.0, 2))
NODES = ("T_pressure_plate", "T_flywheel", "T_air", "T_housing")


def _run(path, **bench):
    return execute(RunRequest("custom", path, steps=STEPS, install_signals=False,
                              bench=SimulatedBench(options={"dropouts": False}, **bench)))


@pytest.mark.parametrize("plant", ["reference", "paper"])
def test_truth_on_the_run_grid_with_units(tmp_path, plant):
    code, _ = _run(tmp_path / "run.h5", plant=plant_named(plant))
    assert code == 0
    run, truth = load_run(tmp_path / "run.h5"), load_truth(tmp_path / "run.h5")
    assert {"time", *NODES} <= set(truth.columns)  # the reference plant: every node, the paper's four among them
    np.testing.assert_array_equal(truth["time"].to_numpy(), run["time"].to_numpy())
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert {k: f["truth"][k].attrs["units"] for k in f["truth"]} == {"time": "s", **{n: "degC" for n in truth
                                                                                         if n != "time"}}
    assert not truth.isna().any().any()
    # the sensors read the truth within their noise (wired PT1000: 0.03 K; node: 0.08 K per sensor, held 50 ms)
    for channel, bound in (("T_air", 0.05), ("T_housing", 0.05), ("T_flywheel_1", 0.1), ("T_flywheel_2", 0.1)):
        at_sensor = channel if channel in truth else "T_flywheel"  # the paper's plant: both sensors on its node
        error = run[channel].to_numpy() - truth[at_sensor].to_numpy()
        assert np.sqrt(np.nanmean(error ** 2)) < bound, channel
    if plant != "paper":  # the reference plant's friction ring is thinner than its plate: docs/plant.md
        return
    # the paper's plate nobody measures: hotter than the flywheel while slipping (smaller capacity, half the heat)
    slipping = run["friction_power"].to_numpy() > 0
    assert slipping.sum() > 100
    plate, flywheel = truth["T_pressure_plate"].to_numpy(), truth["T_flywheel"].to_numpy()
    assert np.mean(plate[slipping] - flywheel[slipping]) > 0.3


def test_truth_kept_through_abort_and_resume(tmp_path):
    path = tmp_path / "run.h5"
    limits = BenchLimits(on_interlock="abort")
    code, summary = _run(path, faults=[Fault(60.0, "controller_silent", target="load")], limits=limits)
    assert code == 1 and summary.status == "aborted"
    first = load_truth(path)
    assert first is not None and len(first) == len(load_run(path)) and not first.isna().any().any()
    code, summary = execute(RunRequest("custom", path, resume=True, install_signals=False,
                                       bench=SimulatedBench(options={"dropouts": False}, limits=limits)))
    assert code == 0, summary
    run, truth = load_run(path), load_truth(path)
    assert len(truth) == len(run) > len(first)
    for name in NODES:  # the rows before the resume as the aborted file held them; the rest computed after it
        np.testing.assert_array_equal(truth[name].to_numpy()[:len(first)], first[name].to_numpy())
        assert not np.isnan(truth[name].to_numpy()).any()


def test_truth_follows_the_hidden_effects_of_the_plant(tmp_path):
    """A cover node, a lagged air sensor and a release path in the plant: /truth holds the cover (K) and the air
    itself (A) beside the sensor's lagged temperature (T_air), the sensors read /truth, sim_truth names the effects."""
    effects = [U.plate_cover(2500.0, 0.1, 0.1).effect, U.air_sensor_lag(10.0).effect,
               U.release_path_conduction(0.3).effect]
    path = tmp_path / "run.h5"
    code, _ = _run(path, plant=ThermalPlant(effects=effects))
    assert code == 0
    run, truth = load_run(path), load_truth(path)
    assert set(truth.columns) == {"time", *NODES, "K", "A"}
    with h5py.File(path, "r") as f:
        recorded = json.loads(f.attrs["sim_truth"])
    assert recorded["effects"] == [e.name for e in effects]
    assert {"C_K", "R_PK", "R_KA", "tau_A", "R_PT"} <= set(recorded["params"])
    error = run["T_air"].to_numpy() - truth["T_air"].to_numpy()
    assert np.sqrt(np.nanmean(error ** 2)) < 0.05
    air, sensor = truth["A"].to_numpy(), truth["T_air"].to_numpy()  # the lag: the sensor trails the heated air
    heating = np.flatnonzero(np.diff(air) > 0)
    assert np.mean(air[heating] - sensor[heating]) > 0
