"""Identification on the simulated bench, where the truth is known (the paper's nonlinear clutch).

The fitting data is a 1 h Table 1 run with the bench's sensor noise, held readings and radio drop-outs;
validation data comes from other seeds. Runs and fits are shared by module fixtures.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.signal import lfilter

from benchlab.cli import main
from benchlab.model.clutch import convection_resistance
from benchlab.identify.api import identify
from benchlab.identify.data import hold_samples, prepare
from benchlab.identify.evaluate import evaluate
from benchlab.identify.fit import residual_index
from benchlab.identify.uncertainty import (CORRELATION_LIMIT, bartlett_bandwidth, identifiability_warnings,
                                          long_run_covariance, prewhitened_long_run_covariance,
                                          power_noise)
from benchlab.identify.metrics import rmse_k
from benchlab.model.params import load_params, paper_params
from benchlab.runfile import load_run, write_run
from benchlab.runner.session import RunRequest, execute
from benchlab.network.simulation import simulate
from protocols.table1 import table1_schedule
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

TRUTH = paper_params("nonlinear")
SPEEDS_RPM = np.linspace(700.0, 3000.0, 47)
# 12 parameters checked at once: under the normal law |z| > 3.5 somewhere has a chance of 0.5 %.
Z_LIMIT = 3.5
LONG_COOLDOWN_S = 300.0


def table1_run(seed: int, hours: float):
    return run_schedule(table1_schedule(seed, duration_s=3600 * hours), ThermalPlant(), seed=seed)


def resistance_error(params) -> float:
    """Largest relative error of R(ω_e), eq. (11), over 700–3000 rpm for both clutch states."""
    channels = {"engine_speed": np.tile(SPEEDS_RPM, 2), "clutch_state": np.repeat([0.0, 1.0], len(SPEEDS_RPM))}
    return float(np.max(np.abs(convection_resistance(params, channels) / convection_resistance(TRUTH, channels) - 1)))


def z_scores(result) -> dict[str, float]:
    se = result.uncertainty.standard_errors
    return {k: (result.params[k] - TRUTH[k]) / se[k] for k in result.params if k in se}


@pytest.fixture(scope="module")
def fitting_run():
    return table1_run(11, 1.0)


@pytest.fixture(scope="module")
def nonlinear(fitting_run):
    return identify([fitting_run], "nonlinear", starts=4)


@pytest.fixture(scope="module")
def linear(fitting_run):
    return identify([fitting_run], "linear", starts=4)


def closed_loop_validation(tmp_path_factory, seed: int, cycles: int):
    """The validation protocol on the closed-loop simulated bench with the paper's plant (the model can match it
    exactly): each long cool-down starts at 70 °C."""
    path = tmp_path_factory.mktemp(f"validation_{seed}") / "validation.h5"
    code, _ = execute(RunRequest("validation", path, seed=seed, cycles=cycles, install_signals=False,
                                 bench=SimulatedBench(ThermalPlant())))
    assert code == 0
    return load_run(path)


@pytest.fixture(scope="module")
def validation_run(tmp_path_factory):
    """Another seed's hot cool-downs and Table 1 draws."""
    return closed_loop_validation(tmp_path_factory, seed=21, cycles=5)


@pytest.fixture(scope="module")
def hot_cooldowns(tmp_path_factory):
    """The long varying cool-downs alone."""
    return closed_loop_validation(tmp_path_factory, seed=5, cycles=0)


def test_fitting_run_has_dropouts(fitting_run, nonlinear):
    assert np.isnan(fitting_run["T_flywheel"]).any()
    assert nonlinear.fit.n_residuals < 3 * len(fitting_run) // 50  # drop-outs skipped, not filled


def test_nonlinear_recovers_the_convection_resistance(nonlinear):
    assert resistance_error(nonlinear.params) < 0.03


def test_truth_within_reported_standard_errors(nonlinear):
    z = z_scores(nonlinear)
    assert len(z) == 12
    assert max(abs(v) for v in z.values()) < Z_LIMIT, z


def test_standard_errors_are_calibrated_over_seeds(nonlinear):
    """Pooled over four 1 h runs, z = (estimate − truth) / SE has an rms near 1: neither too small nor padded.

    (The plain Jacobian gave 3–25; the residual part alone, what a HAC sandwich sees, about 2.)
    """
    z = list(z_scores(nonlinear).values())
    for seed in (12, 13, 14):
        z += list(z_scores(identify([table1_run(seed, 1.0)], "nonlinear", starts=2)).values())
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.6 < rms < 1.6, rms


def test_initial_states_are_fitted_per_run(nonlinear):
    (states,) = nonlinear.initial_states.values()
    assert set(states) == {"T_flywheel", "T_air", "T_housing"}
    for value in states.values():  # the simulated bench starts everything at 22.0 °C
        assert abs(value["value"] - 22.0) < max(4 * value["standard_error"], 0.01)


def test_start_costs_are_on_the_runs_themselves(nonlinear):
    """The scouts fit cheaper versions of the run, but each start's cost in the parameter file is on the run itself:
    the polish, which starts from the best of them, ends at or below it (costs on the scouts' data, an eighth of
    the targets, would lie several times below it)."""
    costs = nonlinear.fit.start_costs
    assert len(costs) == nonlinear.fit.starts >= 2
    assert nonlinear.fit.cost <= costs[0] * (1 + 1e-9)


def test_validation_rmse_at_the_noise_floor(nonlinear, validation_run):
    floor = evaluate(validation_run, TRUTH)["rmse_K"]
    assert evaluate(validation_run, nonlinear.params)["rmse_K"] < 1.2 * floor


def test_nonlinear_beats_linear_on_long_varying_cooldowns(nonlinear, linear, hot_cooldowns):
    """Paper, Fig. 5: with the engine speed or clutch state changing, a constant R misjudges the cool-down."""
    dt = hot_cooldowns.attrs["dt"]
    quiet = np.concatenate([[0], (np.nan_to_num(hot_cooldowns["friction_power"].to_numpy()) == 0).astype(int), [0]])
    edges = np.flatnonzero(np.diff(quiet))
    spans = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if (b - a) * dt >= LONG_COOLDOWN_S]
    assert len(spans) >= 2
    keep = np.zeros(len(hot_cooldowns), dtype=bool)
    for a, b in spans:
        keep[a:b] = True
    assert np.nanmax(hot_cooldowns["T_flywheel"].to_numpy()[keep]) > 60.0
    measured = hot_cooldowns[keep]
    errors = {name: rmse_k(measured, simulate(hot_cooldowns, result.params)[keep])
              for name, result in (("linear", linear), ("nonlinear", nonlinear))}
    assert errors["nonlinear"] * 2 <= errors["linear"], errors


def test_fixed_parameter_is_held(fitting_run):
    result = identify([fitting_run], "nonlinear", fixed={"C_T": 12000.0}, starts=2)
    assert result.params["C_T"] == 12000.0
    assert "C_T" not in result.uncertainty.standard_errors
    assert result.params["C_F"] == pytest.approx(TRUTH["C_F"], rel=0.05)


def test_two_runs_fitted_at_once():
    runs = [table1_run(31, 0.5), table1_run(32, 0.5)]
    result = identify(runs, "nonlinear", starts=2)
    assert len(result.fitting) == 2 and len(result.initial_states) == 2
    per_run = residual_index([prepare(run, name=f"run{i}") for i, run in enumerate(runs)])
    assert result.fit.n_residuals == sum(len(index) for index in per_run)
    assert resistance_error(result.params) < 0.03
    assert max(abs(v) for v in z_scores(result).values()) < Z_LIMIT


def test_blanked_air_sensor_block_is_skipped(fitting_run, nonlinear):
    run = fitting_run.copy()
    run.attrs.update(fitting_run.attrs)
    t = run["time"].to_numpy()
    run.loc[(t >= 1200.0) & (t < 1800.0), "T_air"] = np.nan
    result = identify([run], "nonlinear", starts=4)
    assert result.fit.n_residuals < nonlinear.fit.n_residuals - 1000
    assert resistance_error(result.params) < 0.03
    assert max(abs(v) for v in z_scores(result).values()) < Z_LIMIT


def test_correlation_warnings_group_exactly_the_close_pairs(nonlinear):
    """One line per cluster of parameters connected by |corr| > limit: two parameters share a line exactly when a
    chain of close pairs joins them."""
    u = nonlinear.uncertainty
    names = [n for n in nonlinear.params.keys() & u.standard_errors.keys() if u.standard_errors[n] > 0]
    index = {n: u.names.index(n) for n in names}
    lines = [w.split(" are hard to tell apart")[0].replace(" and ", ", ").split(", ")
             for w in u.warnings if "are hard to tell apart" in w]
    line_of = {name: k for k, members in enumerate(lines) for name in members}
    assert sum(map(len, lines)) == len(line_of)  # each parameter in one line at most
    joined = {n: {n} for n in names}
    for a in names:
        for b in names:
            corr = u.correlation[index[a], index[b]]
            if np.isfinite(corr) and abs(corr) > CORRELATION_LIMIT:
                union = joined[a] | joined[b]
                for n in union:
                    joined[n] = union
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            together = a in line_of and line_of.get(b) == line_of[a]
            assert together == (b in joined[a]), (a, b)
    assert any(w.startswith("C_P is seen only through") for w in u.warnings)


def test_identifiability_warnings_on_a_known_matrix():
    corr = np.array([[1.0, 0.97, 0.2], [0.97, 1.0, -0.94], [0.2, -0.94, 1.0]])
    warnings = identifiability_warnings(["x", "y", "w"], [1.0, 2.0, 3.0], [0.1, 1.5, 0.1], corr, [1.0, 1.0, 1e-9])
    assert warnings == ["x and y are hard to tell apart (correlation +0.970)",
                        "y is poorly excited by the data (standard error 75 %)",
                        "w has no visible effect on the measured channels"]


def test_newey_west_matches_its_definition():
    rng = np.random.default_rng(1)
    scores = rng.standard_normal((500, 3)).cumsum(axis=0) * 0.1 + rng.standard_normal((500, 3))
    bandwidth = 17
    expected = scores.T @ scores
    for lag in range(1, bandwidth):
        gamma = scores[lag:].T @ scores[:-lag]
        expected += (1 - lag / bandwidth) * (gamma + gamma.T)
    assert np.allclose(long_run_covariance(scores, bandwidth), expected)


def test_prewhitened_newey_west_holds_a_strongly_correlated_score():
    """AR(1) scores (phi 0.9, two correlated columns): the long-run covariance of the sum is n/(1-phi)^2 times
    the innovations'. Prewhitened it comes out within 10 % on average over 30 runs of 2400 steps; the plain
    Bartlett estimate at Andrews' bandwidth falls short (why identify prewhitens)."""
    rng = np.random.default_rng(3)
    steps, phi = 2400, 0.9
    truth = steps * np.array([1.0, 2.0]) / (1 - phi) ** 2
    prewhitened, plain = [], []
    for _ in range(30):
        ar = lfilter([1.0], [1.0, -phi], rng.standard_normal((steps, 2)), axis=0)
        scores = np.column_stack([ar[:, 0], ar[:, 0] + ar[:, 1]])
        prewhitened.append(np.diag(prewhitened_long_run_covariance(scores)[0]) / truth)
        plain.append(np.diag(long_run_covariance(scores, bartlett_bandwidth(scores))) / truth)
    assert np.all(np.abs(np.mean(prewhitened, axis=0) - 1) < 0.1)
    assert np.all(np.mean(plain, axis=0) < np.mean(prewhitened, axis=0))


def test_power_noise_from_the_full_rate_record():
    """A slipping ramp with 20 W of white noise per 10 ms sample: each 0.5 s mean carries 20/√50 W."""
    rng = np.random.default_rng(2)
    power = np.zeros(50 * 400)
    power[5000:15000] = np.linspace(8000.0, 100.0, 10000) + rng.normal(0.0, 20.0, 10000)
    sigma = power_noise(pd.DataFrame({"friction_power": power}), 50, 400)
    assert np.all(sigma[:100] == 0) and np.all(sigma[300:] == 0)
    assert np.median(sigma[100:300]) == pytest.approx(20.0 / np.sqrt(50), rel=0.1)


@pytest.fixture(scope="module")
def run_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("identify")
    for name, seed in (("run.h5", 41), ("val.h5", 42)):
        run = table1_run(seed, 0.5)
        write_run(d / name, run, run.attrs["dt"], protocol="table1")
    return d


def test_cli_writes_a_contract_parameter_file(run_files, capsys):
    out = run_files / "P.json"
    code = main(["identify", str(run_files / "run.h5"), "--model", "nonlinear", "--out", str(out),
                 "--validate", str(run_files / "val.h5"), "--starts", "2", "--fix", "C_T=13000"])
    assert code == 0
    params = load_params(out)
    assert params.model == "nonlinear" and params["C_T"] == 13000.0
    assert set(params) >= {"C_P", "C_F", "C_A", "C_T", "R_AT", "R_Feng", "R_Tamb", "R0", "a1", "b1", "a2", "b2"}
    doc = json.loads(out.read_text())
    assert list(doc)[:3] == ["model", "params", "units"]
    assert set(doc["uncertainty"]) == set(params) - {"C_T"}
    corr = np.array(doc["correlation"]["matrix"])
    assert doc["correlation"]["names"] == list(doc["uncertainty"]) and np.allclose(np.diag(corr), 1.0)
    assert set(doc["fit"]["validation"]) == {str(run_files / "val.h5")}
    assert doc["fit"]["validation"][str(run_files / "val.h5")]["rmse_K"] < 0.1
    assert set(doc["fit"]["residuals"][str(run_files / "run.h5")]) == {"T_flywheel", "T_air", "T_housing"}
    assert "validation" in capsys.readouterr().out


def _without_channel(run_files, channel: str):
    run = load_run(run_files / "run.h5")
    path = run_files / f"no_{channel}.h5"
    write_run(path, run.drop(columns=[channel]), run.attrs["dt"], protocol="table1")
    return path


@pytest.mark.parametrize("case", ["missing file", "fix not a number", "fix unknown name", "fix out of bounds",
                                  "missing channel"])
def test_cli_bad_input_exits_2_with_one_line(run_files, tmp_path, capsys, case):
    run, extra = str(run_files / "run.h5"), []
    if case == "missing file":
        run = str(tmp_path / "nowhere.h5")
    elif case == "fix not a number":
        extra = ["--fix", "C_T=warm"]
    elif case == "fix unknown name":
        extra = ["--fix", "C_X=1"]
    elif case == "fix out of bounds":
        extra = ["--fix", "C_T=-5"]
    else:
        run = str(_without_channel(run_files, "T_air"))
    code = main(["identify", run, "--out", str(tmp_path / "P.json"), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "P.json").exists()


def test_targets_are_placed_at_their_readings_mean_age():
    """Air warming at 0.02 K/s read every 0.5 s and held on a 10 ms grid: a grid value is 0.245 s old on average,
    0.0049 K behind; the targets at the block starts are the true ramp, not the held one (data.prepare)."""
    dt, n = 0.01, 6000
    t = np.arange(n) * dt
    truth = 30.0 + 0.02 * t
    held = np.repeat(truth[::50], 50)
    run = pd.DataFrame({"time": t, "engine_speed": 1000.0, "clutch_speed": 1000.0, "clutch_torque": 0.0,
                        "clutch_state": 1.0, "friction_power": 0.0, "T_flywheel": held, "T_air": held,
                        "T_housing": held, "T_ambient": 22.0})
    run.attrs["dt"] = dt
    data = prepare(run, 1.0)
    assert hold_samples(held) == 50 and hold_samples(truth) == 1
    inner = slice(1, len(data) - 1)
    assert np.max(np.abs(data.targets["T_air"][inner] - truth[::100][: len(data)][inner])) < 5e-4  # half a sample of rounding
    assert np.max(np.abs(np.mean(held.reshape(-1, 100), axis=1) - truth[50::100])) > 0.004  # unshifted: 0.0049 K


def test_quantisation_plateaus_of_a_slow_signal_are_not_holds():
    t = np.arange(20000) * 0.01
    slow = np.round((30.0 + 0.5 * np.sin(t / 40.0)) / 0.1) * 0.1  # a 0.1 K sensor on a slow swing: long, uneven runs
    assert hold_samples(slow) == 1


def test_temperatures_that_start_late_identify_like_the_whole_run():
    """A logger that started 3 s after the run (an imported file): the flywheel's first reading comes after the first
    launch heated it, so t = 0 is fitted, not taken from it (before: C_P 414 and C_A 6121 J/K against 1800 and 2000)."""
    run = run_schedule(table1_schedule(5, duration_s=1800), ThermalPlant(paper_params("linear"), []), seed=5)
    late = run.copy()
    late.attrs = dict(run.attrs)
    late.loc[: int(3 / run.attrs["dt"]), [c for c in run.columns if c.startswith("T_")]] = np.nan
    truth = paper_params("linear")
    found = identify([late], "linear", starts=3).params
    for name in ("C_P", "C_F", "C_A", "C_T", "R0"):
        assert found[name] == pytest.approx(truth[name], rel=0.05), name
