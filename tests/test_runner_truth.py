"""The full stack (runner, drivers, emulated bench) tells the truth: the run file agrees with the plant and the CAN log.

- At the plant's true parameters a Table 1 run through the drivers sits at the sensor-noise floor (0.041 K on the
  batch simulator's exact inputs); with CAN frames stamped at poll time it sat at 0.10 K.
- Identified from such a run (≥ 40 min), the nonlinear model recovers the plant: R(ω_e) within 2 % over
  700–3000 rpm in both clutch states, R_Feng within 5 %, fit RMSE within 1.2x the noise floor.
- The friction energy in /aligned equals the energy integrated from the raw CAN log (BLF, read back by python-can and
  decoded by cantools from drivers/bench.dbc, independently of benchlab's codec) at the frames' own times: within
  0.4 % over the run and 1 % per launch.
"""

import can
import cantools
import h5py
import numpy as np
import pytest

from benchlab.model.clutch import convection_resistance
from benchlab.identify.api import identify
from benchlab.identify.evaluate import evaluate
from benchlab.model.params import paper_params
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, can_log_path, execute
from drivers import can_signals as sig
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant

FLOOR_K = 0.045  # sensor-noise floor of a Table 1 run: node 0.08 K per sensor (two averaged), wired 0.03 K


@pytest.fixture(scope="module")
def table1_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("truth") / "t1.h5"
    code, _ = execute(RunRequest(protocol="table1", out=path, seed=4, duration_s=2400,
                                 bench=SimulatedBench(ThermalPlant()), install_signals=False))
    assert code == 0
    return path


def test_full_stack_run_matches_model_at_truth(table1_run):
    assert evaluate(load_run(table1_run), paper_params("nonlinear"))["rmse_K"] < FLOOR_K


def test_identified_from_a_driver_run_recovers_the_plant(table1_run):
    run = load_run(table1_run)
    result = identify([run], "nonlinear", starts=4)
    truth = paper_params("nonlinear")
    rpm = np.linspace(700.0, 3000.0, 47)
    for state in (0.0, 1.0):
        channels = {"engine_speed": rpm, "clutch_state": np.full_like(rpm, state)}
        fitted = np.asarray(convection_resistance(result.params, channels))
        true = np.asarray(convection_resistance(truth, channels))
        assert np.max(np.abs(fitted / true - 1.0)) < 0.02, state
    assert abs(result.params["R_Feng"] / truth["R_Feng"] - 1.0) < 0.05
    assert evaluate(run, result.params)["rmse_K"] < 1.2 * FLOOR_K


def _log_power(path) -> tuple[np.ndarray, np.ndarray]:
    """Friction power at each clutch status frame of the BLF log, speeds interpolated to the frame's own time."""
    db = cantools.database.load_file(str(sig.BENCH_DBC))
    names = {db.get_message_by_name(m).frame_id: m for m in ("DriveMotor_Status", "ClutchActuator_Status",
                                                           "LoadMachine_Status")}
    rows: dict[str, list] = {m: [] for m in names.values()}
    for msg in can.LogReader(str(path)):
        if msg.is_rx and msg.arbitration_id in names:
            name = names[msg.arbitration_id]
            rows[name].append((msg.timestamp, db.decode_message(name, msg.data, decode_choices=False)))
    t_drive = np.array([t for t, _ in rows["DriveMotor_Status"]])
    t_load = np.array([t for t, _ in rows["LoadMachine_Status"]])
    t = np.array([t for t, _ in rows["ClutchActuator_Status"]])
    engine = np.interp(t, t_drive, [v["DM_Speed"] for _, v in rows["DriveMotor_Status"]])
    clutch = np.interp(t, t_load, [v["LM_Speed"] for _, v in rows["LoadMachine_Status"]]) * 15.0
    torque = np.array([v["CA_Torque"] for _, v in rows["ClutchActuator_Status"]])
    slipping = np.array([v["CA_ClampState"] for _, v in rows["ClutchActuator_Status"]]) == sig.CLAMP_SLIPPING
    return t, np.where(slipping, np.abs(torque * (engine - clutch)) * np.pi / 30.0, 0.0)


def test_aligned_friction_energy_equals_the_can_log(table1_run):
    run = load_run(table1_run)
    with h5py.File(table1_run, "r") as f:
        assert f.attrs["can_log"] == can_log_path(table1_run).name
    t, power = _log_power(can_log_path(table1_run))
    held = np.diff(t, append=t[-1])  # each frame's value holds until the next frame (zero-order hold)
    log_energy = power * held
    aligned = np.nan_to_num(run["friction_power"].to_numpy()) * run.attrs["dt"]
    grid = run["time"].to_numpy()
    assert abs(aligned.sum() / log_energy.sum() - 1.0) < 0.004
    slipping = power > 0
    starts = np.flatnonzero(slipping & ~np.r_[False, slipping[:-1]])
    ends = np.flatnonzero(slipping & ~np.r_[slipping[1:], False])
    assert len(starts) > 20
    for a, b in zip(starts, ends):
        in_launch = (grid >= t[a] - 1e-6) & (grid <= t[b] + 1e-6)
        assert abs(aligned[in_launch].sum() / log_energy[a:b + 1].sum() - 1.0) < 0.01, (t[a], t[b])
