"""Wear prediction (issue 7): friction energy, engagements, wear law, health, remaining life, temperature effect."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchlab.errors import InputError
from benchlab.model.params import load_params, paper_params
from benchlab.wear import WearState, analyse_wear, default_clutch
from benchlab.wear.compare import temperature_sensitivity
from benchlab.drivetrain import RPM
from benchlab.wear.energy import engagement_spans, run_friction_power
from benchlab.wear.health import assess
from benchlab.wear.life import remaining_life
from benchlab.wear.model import side_increments, wear_history
from benchlab.wear.online import OnlineWear
from benchlab.wear.thermal import heat_split
from benchlab.wear.torque import ACTUATOR_CHANNEL, normal_force, transmissible_torque
from protocols.schedule import Step
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import drive_schedule, run_schedule


def hot_schedule(cycles: int = 10) -> tuple[Step, ...]:
    """Hill starts against a load the clutch torque cannot move: long full-slip engagements, linings past 200 degC."""
    steps: list[Step] = []
    for c in range(cycles):
        steps += [Step("launch", 10.0, 2000.0, 65.0, 1200.0, c), Step("drive", 20.0, 2000.0, 65.0, 1200.0, c),
                  Step("open", 20.0, 2000.0, 0.0, 1200.0, c)]
    return tuple(steps)


@pytest.fixture(scope="module")
def report(short_run):
    return analyse_wear(short_run, paper_params(), horizon=20_000, paths=300, seed=3)


@pytest.fixture(scope="module")
def hot_run():
    return run_schedule(hot_schedule(), ThermalPlant(), seed=11)


@pytest.fixture(scope="module")
def hot_report(hot_run):
    return analyse_wear(hot_run, paper_params(), horizon=1000, paths=50)


def test_friction_energy_is_the_zoh_integral_of_power(short_run, report):
    dt = short_run.attrs["dt"]
    recorded = float(np.sum(short_run["friction_power"]) * dt)
    slip = (short_run["engine_speed"] - short_run["clutch_speed"]).to_numpy() * RPM
    slipping = (short_run["clutch_state"].to_numpy() == 1) & (short_run["friction_power"].to_numpy() > 0)
    independent = float(np.trapezoid(np.where(slipping, np.abs(short_run["clutch_torque"].to_numpy() * slip), 0.0),
                                     dx=dt))
    truth, _ = drive_schedule(table1_schedule(7, duration_s=1200), dt)
    true_energy = float(np.sum(truth["friction_power"]) * dt)
    assert report.friction_energy_j == pytest.approx(recorded, rel=5e-3)
    assert report.friction_energy_j == pytest.approx(independent, rel=5e-3)
    assert report.friction_energy_j == pytest.approx(true_energy, rel=5e-3)
    sides = report.engagements[["energy_plate_J", "energy_flywheel_J"]].to_numpy().sum()
    assert sides == pytest.approx(report.friction_energy_j, rel=1e-9)


def test_engagements_match_launch_events(short_run, report):
    events = short_run.attrs["events"]
    launches = [e["time"] for e in events if e["event"] == "launch_start"]
    ends = {e["cycle"]: e["time"] for e in events if e["event"] in ("synchronised", "slip_time_limit")}
    assert len(report.engagements) == len(launches)
    np.testing.assert_allclose(report.engagements["start_s"], launches, atol=0.05)
    synced = [e["cycle"] for e in events if e["event"] == "synchronised"]
    for cycle in synced:
        assert report.engagements["end_s"].iloc[cycle] == pytest.approx(ends[cycle], abs=0.1)
    assert (report.engagements["peak_power_W"] > 0).all()
    table = report.engagements
    assert (table["slip_time_s"] <= table["end_s"] - table["start_s"] + 1e-9).all()


def test_engagement_gaps_are_bridged_only_when_tiny():
    active = np.zeros(1000, dtype=bool)
    active[100:200] = active[203:300] = True  # 3-sample flicker at synchronisation
    active[500:600] = True  # 2 s later: a new engagement
    assert engagement_spans(active, 0.01) == [(100, 300), (500, 600)]


def test_engagement_count_on_hot_run(hot_run):  # launches that never synchronise
    spans = engagement_spans(run_friction_power(hot_run) > 0, hot_run.attrs["dt"])
    assert len(spans) == sum(e["event"] == "launch_start" for e in hot_run.attrs["events"])


def test_wear_is_monotone_and_health_falls(report):
    for name, values in report.history.cumulative.items():
        assert np.all(np.diff(values) >= 0), name
    assert report.final_state().wear_plate_mm > 0 and report.final_state().wear_flywheel_mm > 0
    assert 0.0 < report.health.health < 1.0 and not report.health.worn


def test_hotter_linings_wear_more():
    spec = default_clutch()
    power = np.full(1000, 5000.0)
    temps = np.arange(20.0, 401.0, 20.0)
    wear = [side_increments(spec, power, np.full(1000, t), 0.01)[0].sum() for t in temps]
    assert np.all(np.diff(wear) >= 0) and wear[-1] > 5 * wear[0]
    cool = wear_history(spec, power, 0.5, np.full(1000, 60.0), np.full(1000, 60.0), 0.01).final()
    hot = wear_history(spec, power, 0.5, np.full(1000, 260.0), np.full(1000, 60.0), 0.01).final()
    assert hot.wear_plate_mm > 2 * cool.wear_plate_mm and hot.loss_plate > cool.loss_plate
    assert hot.wear_flywheel_mm == pytest.approx(cool.wear_flywheel_mm)


def test_hot_run_wears_more_per_joule(report, hot_report):
    hot = hot_report
    per_joule = lambda r: r.final_state().wear_plate_mm / r.friction_energy_j  # noqa: E731
    assert hot.temperatures["T_pressure_plate"].max() > 200.0
    assert per_joule(hot) > 1.5 * per_joule(report)


def test_plate_runs_hotter_and_split_key_moves_heat(short_run, report):
    mean_temperature = {side: report.side_summary(side)["mean_lining_temperature_C"] for side in ("plate", "flywheel")}
    assert mean_temperature["plate"] > mean_temperature["flywheel"]
    params = paper_params()
    params["split"] = 0.7
    shifted = analyse_wear(short_run, params, horizon=1000, paths=20)
    assert shifted.split == 0.7
    assert shifted.side_summary("plate")["energy_J"] == pytest.approx(0.7 * shifted.friction_energy_j)
    assert shifted.temperatures["T_pressure_plate"].max() > report.temperatures["T_pressure_plate"].max()
    assert shifted.temperatures["T_flywheel"].max() < report.temperatures["T_flywheel"].max()


def test_model_temperatures_beat_a_constant_against_the_truth(short_run, report, hot_run, hot_report):
    results = [temperature_sensitivity(run, paper_params(), temperatures=r.temperatures)
               for run, r in ((short_run, report), (hot_run, hot_report))]
    for result in results:
        assert result["model"]["error_pct"] < 1.0
        assert result["model"]["error_pct"] < result["constant"]["error_pct"]
    assert results[1]["constant"]["error_pct"] > 30.0  # ignoring the lining temperature badly underestimates hot wear
    assert results[1]["constant"]["wear_plate_mm"] < results[1]["true"]["wear_plate_mm"]


def test_health_criteria():
    spec = default_clutch()
    limit = spec.height_mm - spec.min_height_mm
    height = assess(spec, WearState(wear_plate_mm=limit, wear_flywheel_mm=0.1))
    assert height.worn and height.limited_by == "lining_height" and height.health == 0.0
    glazed = assess(spec, WearState(loss_plate=0.3, loss_flywheel=0.3))
    assert glazed.worn and glazed.limited_by == "torque"
    assert glazed.transmissible_torque_Nm < spec.max_engine_torque_nm
    new = assess(spec, WearState())
    assert not new.worn and new.health == 1.0 and new.new_torque_Nm == pytest.approx(
        spec.faces * spec.mean_radius_m * 0.30 * normal_force(spec, 0.0, spec.rating_temperature_c), rel=1e-2)
    worn_spring = transmissible_torque(spec, 1.4, 1.4, 0.0, 0.0)
    assert worn_spring < spec.max_engine_torque_nm  # the diaphragm spring's force drop alone wears it out


def test_monte_carlo_percentiles_are_stable(report):
    increments = report.engagements[["wear_plate_mm", "wear_flywheel_mm", "loss_plate", "loss_flywheel"]].to_numpy()
    cycle = report.engagements["cycle_s"].to_numpy()
    state = report.final_state()
    runs = [remaining_life(report.spec, state, increments, cycle, 20_000, paths=400, seed=s) for s in (1, 1, 2)]
    first, again, other = (r.percentiles(r.engagements) for r in runs)
    assert first == again
    for key in ("p10", "p50", "p90"):
        assert other[key] == pytest.approx(first[key], rel=0.08)
    assert first["p10"] < first["p50"] < first["p90"]
    assert report.life.as_dict()["censored_fraction"] == 0.0
    hours = runs[0].percentiles(runs[0].hours)
    assert hours["p10"] < hours["p50"] < hours["p90"]


def test_failure_probability_rises_with_horizon(report):
    increments = report.engagements[["wear_plate_mm", "wear_flywheel_mm", "loss_plate", "loss_flywheel"]].to_numpy()
    p50 = report.life.percentiles(report.life.engagements)["p50"]
    probs = [remaining_life(report.spec, report.final_state(), increments, report.engagements["cycle_s"].to_numpy(),
                            int(h * p50), paths=300, seed=5).p_fail_within_horizon for h in (0.3, 1.0, 3.0)]
    assert probs[0] < 0.05 and 0.3 < probs[1] < 0.7 and probs[2] > 0.95


def test_worn_clutch_has_no_life_and_quiet_run_has_no_end(report):
    spec = default_clutch()
    worn = remaining_life(spec, WearState(loss_plate=0.5, loss_flywheel=0.5), np.ones((3, 4)), np.ones(3), 10)
    assert np.all(worn.engagements == 0) and worn.p_fail_within_horizon == 1.0
    idle = remaining_life(spec, WearState(), np.zeros((0, 4)), np.zeros(0), 10, paths=5)
    assert idle.percentiles(idle.engagements)["p50"] is None and idle.p_fail_within_horizon == 0.0


def test_mu_is_estimated_from_actuator_position(short_run):
    spec = default_clutch()
    run = short_run.copy()
    run.attrs = dict(short_run.attrs)
    # Synthesise the actuator position a clutch with μ = 0.25 would need for the measured torque.
    spring = normal_force(spec, 0.0, run["T_air"].to_numpy())
    share = np.abs(run["clutch_torque"].to_numpy()) / (spec.faces * spec.mean_radius_m * 0.25 * spring)
    x, y = spec.maps["actuator"].as_lists()
    run[ACTUATOR_CHANNEL] = np.interp(share, y[::-1], x[::-1])
    result = analyse_wear(run, paper_params(), spec, horizon=100, paths=10)
    mu = result.mu_summary()
    assert mu is not None and mu["samples"] > 1000
    assert mu["median"] == pytest.approx(0.25, rel=0.02)
    assert mu["model_median"] > 0.28  # the map says 0.30: the estimate exposes the drift
    assert analyse_wear(short_run, paper_params(), spec, horizon=100, paths=10).mu_summary() is None


def test_online_update_matches_offline(short_run, report):
    n = 40_000
    dt = short_run.attrs["dt"]
    x0 = report.temperatures.iloc[0].to_numpy()
    online = OnlineWear(paper_params(), default_clutch(), dt, [x0[0], x0[1], x0[2], x0[3]])
    speed, state = short_run["engine_speed"].to_numpy(), short_run["clutch_state"].to_numpy()
    amb = short_run["T_ambient"].to_numpy()
    for k in range(n):
        online.step(speed[k], state[k] >= 0.5, report.power_w[k], amb[k], amb[k])
    expected = report.temperatures.iloc[n].to_numpy()
    np.testing.assert_allclose(online.x, expected, atol=0.05)
    offline = {name: values[n - 1] for name, values in report.history.cumulative.items()}
    assert online.wear[0] == pytest.approx(offline["wear_plate_mm"], rel=1e-3)
    assert online.wear[1] == pytest.approx(offline["wear_flywheel_mm"], rel=1e-3)
    assert online.wear[2] == pytest.approx(offline["loss_plate"], rel=1e-3)


def test_split_key_is_read_from_either_place_in_the_params_file(tmp_path):
    doc = {"model": "nonlinear", "params": dict(paper_params())}
    for where, value in (("top", 0.6), ("params", 0.65)):
        path = tmp_path / f"{where}.json"
        body = {**doc, "split": value} if where == "top" else {**doc, "params": {**doc["params"], "split": value}}
        path.write_text(json.dumps(body))
        assert heat_split(load_params(path)) == value
    assert heat_split(paper_params()) == 0.5
    bad = paper_params()
    bad["split"] = 1.5
    with pytest.raises(InputError, match="split"):
        heat_split(bad, "p.json")
