"""Hidden effects in simulated data: diagnose must find them, name them, and measure the true gain.

Each case runs the whole method (baseline fit, screening, blocked cross-validation, re-check) on a
1 h Table 1 run from the simulated bench, whose plant holds effects the baseline model lacks.
The truth's own error, the floor no model can beat, is the RMSE of the true sensor temperatures
against the same fitting targets; the gain possible is 1 - floor / baseline.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.diagnose import diagnose
from benchlab.diagnose.engine import STEP_S
from benchlab.identify.data import prepare
from benchlab.identify.fit import fit_multistart
from benchlab.model.catalog import model_spec
from benchlab.model.params import paper_params
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

HOUR_S = 3600.0
GAIN_TOLERANCE_PCT = 10.0  # measured gain vs the truth's: held-out parameter noise is a few % of a floor-level RMSE


def _bench(effects, seed: int, truth: str = "nonlinear"):
    """The simulated bench with `truth`'s clutch plus `effects`, and a 1 h Table 1 run on it."""
    plant = P.ThermalPlant(paper_params(truth), effects)
    return plant, run_schedule(table1_schedule(seed, duration_s=HOUR_S), plant, seed=seed)


def _accepted_as_documented(result: dict) -> None:
    """Every finding passed the documented test, whatever path (greedy round, drop-one re-check) it came through."""
    method = result["method"]
    for f in result["findings"]:
        assert f["p_value"] < method["alpha"] and f["gain_pct"] >= method["min_gain_pct"], f


def names_as_promised(finding: dict, truth: set[tuple[str | None, str]], alpha: float) -> bool:
    """The finding names a truth, or a truth is listed in its alternatives as not beaten at alpha and adds no fewer
    parameters: the method names the simplest of the explanations it cannot tell apart (docs/diagnose.md, step 7)."""
    if (finding["signal"], finding["mechanism"]) in truth:
        return True
    return any((a["signal"], a["mechanism"]) in truth and a["p_vs_finding"] >= alpha
               and a["n_params"] >= len(finding["params"]) for a in finding["alternatives"])


def _sensor_truth(plant: P.ThermalPlant, run) -> dict[str, np.ndarray]:
    seconds = run["time"].to_numpy() - run["time"].iloc[0]  # a drifting sensor's clock
    return plant.sensor_temperatures(run.attrs["true_states"], seconds)


def _floor(plant: P.ThermalPlant, run) -> float:
    """RMSE of the true sensor temperatures against the fitting targets: what a perfect model scores."""
    data = prepare(run, STEP_S)
    truth = _sensor_truth(plant, run)
    squared = []
    for channel, target in data.targets.items():
        valid = np.isfinite(target)
        squared.append((truth[channel][:: data.block][: len(target)][valid] - target[valid]) ** 2)
    return float(np.sqrt(np.mean(np.concatenate(squared))))


def _true_gain_pct(result: dict, floor: float) -> float:
    return 100.0 * (1.0 - floor / result["baseline"]["rmse_K"])


def _custom_torque_heat(watts: float) -> P.Effect:
    """A heat flow into the chamber air saturating with clutch torque: no physical term of the library has it."""
    return P.custom_source("torque_heat", "A", "clutch_torque", "other",
                           lambda ch: watts * np.tanh(np.abs(ch["clutch_torque"]) / 40.0))


CUSTOM_SOURCES = {"torque_heat"}  # heat flows into a node (sim_bench.plant.custom_source), "other" by their Effect

HIDDEN = [  # (effect, seed, signal, mechanism): two magnitudes per effect, seeds not used while building
    (P.slip_convection(0.4), 101, "slip_speed", "convection"),
    (P.slip_convection(0.8), 102, "slip_speed", "convection"),
    (P.heat_split(0.62), 103, "friction_power", "heat_split"),
    (P.heat_split(0.4), 104, "friction_power", "heat_split"),
    (P.gearbox_churning(30.0), 105, "clutch_speed", "heat_source"),
    (P.gearbox_churning(80.0), 106, "clutch_speed", "heat_source"),
    (P.engine_heat(25.0), 107, "engine_speed", "heat_source"),
    (P.engine_heat(50.0), 108, "engine_speed", "heat_source"),
    (P.plate_conduction(0.4), 109, "clutch_state", "conduction"),
    (P.plate_conduction(0.8), 110, "clutch_state", "conduction"),
    (P.sensor_lag(10.0), 111, "T_flywheel", "sensor"),
    (P.sensor_lag(40.0), 112, "T_flywheel", "sensor"),
    (P.extra_mass(2000.0, 0.3), 113, None, "capacity"),
    (P.extra_mass(4000.0, 0.15), 114, None, "capacity"),
    (P.radiation(0.08), 117, "T_flywheel", "other"),
    (P.radiation(0.2), 118, "T_flywheel", "other"),
    (P.sensor_calibration("T_housing", -0.9, 1.02), 191, "T_housing", "sensor"),  # one size each of two outputs
    (P.sensor_calibration("T_air", 1.4, 0.985), 192, "T_air", "sensor"),
    (_custom_torque_heat(40.0), 115, "clutch_torque", "other"),
    (_custom_torque_heat(80.0), 116, "clutch_torque", "other"),
]


@pytest.mark.parametrize("effect,seed,signal,mechanism", HIDDEN,
                         ids=[f"{e.name}-{s}" for e, s, _, _ in HIDDEN])
def test_hidden_effect_is_named_first_with_the_true_gain(effect, seed, signal, mechanism):
    plant, run = _bench([effect], seed)
    result = diagnose([run], baseline="nonlinear")
    assert result["findings"], f"nothing found; baseline {result['baseline']['rmse_K']:.4f} K"
    first = result["findings"][0]
    # a custom heat flow ("other": no physical term had its form) may be named what it is, a heat source on its signal,
    # where a generated source fits it
    accepted = {(signal, mechanism)} | ({(signal, "heat_source")} if effect.name in CUSTOM_SOURCES else set())
    assert names_as_promised(first, accepted, result["method"]["alpha"]), first
    floor = _floor(plant, run)
    assert first["gain_pct"] == pytest.approx(_true_gain_pct(result, floor), abs=GAIN_TOLERANCE_PCT)


@pytest.mark.parametrize("resistance,seed", [(0.5, 119), (0.8, 120)])
def test_convection_that_depends_on_the_temperature_difference_is_named(resistance, seed):
    """Natural convection beside eq. (11): plate and flywheel to air through R_n (|dT| / 10 K)^-0.25 of the plant's own
    temperatures (issue 31). Named first as convection on |T_flywheel - T_air|. The law reads the measured difference,
    and the plate's own is not measured (the flywheel's stands in for it), so the model gets near the floor, not onto
    it, and its gain is not held to the exact effects' 10 points (docs/diagnose.md: 85.8 % against the truth's 83.2 %
    and 63.8 % against 73.9 %, 1.13x and 1.39x the floor)."""
    plant, run = _bench([P.natural_convection(resistance)], seed)
    result = diagnose([run], baseline="nonlinear")
    assert result["findings"], f"nothing found; baseline {result['baseline']['rmse_K']:.4f} K"
    first = result["findings"][0]
    assert names_as_promised(first, {("T_flywheel", "convection")}, result["method"]["alpha"]), first
    assert first["signals"] == ["T_flywheel", "T_air"]
    assert result["best"]["rmse_K"] < 1.5 * _floor(plant, run)


@pytest.mark.parametrize("effect,seed", [(P.gearbox_churning(50.0), 151), (P.heat_split(0.6), 152),
                                         (P.sensor_lag(15.0), 153)], ids=["churning", "split", "lag"])
def test_default_linear_baseline_on_a_linear_clutch_names_the_hidden_effect(effect, seed):
    plant, run = _bench([effect], seed, truth="linear")
    result = diagnose([run])
    assert [(f["signal"], f["mechanism"]) for f in result["findings"]] == [(effect.signal, effect.mechanism)]
    assert result["findings"][0]["gain_pct"] == pytest.approx(_true_gain_pct(result, _floor(plant, run)),
                                                              abs=GAIN_TOLERANCE_PCT)


@pytest.mark.parametrize("effect,seed", [(P.gearbox_churning(50.0), 161), (P.extra_mass(2500.0, 0.25), 162)],
                         ids=["churning", "mass"])
def test_linear_baseline_finds_the_convection_and_the_hidden_effect_and_reaches_the_floor(effect, seed):
    plant, run = _bench([effect], seed)
    result = diagnose([run], baseline="linear")
    named = {(f["signal"], f["mechanism"]) for f in result["findings"]}
    assert named == {("engine_speed", "convection"), (effect.signal, effect.mechanism)}
    _accepted_as_documented(result)
    assert result["best"]["rmse_K"] < 1.25 * _floor(plant, run)


def test_convection_hidden_from_the_linear_model_is_found_with_its_gain():
    plant, run = _bench([], seed=121)
    result = diagnose([run], baseline="linear")
    first = result["findings"][0]
    assert (first["signal"], first["mechanism"]) == ("engine_speed", "convection")
    assert first["gain_pct"] == pytest.approx(_true_gain_pct(result, _floor(plant, run)), abs=GAIN_TOLERANCE_PCT)


@pytest.mark.parametrize("seed,truth", [(131, "nonlinear"), (132, "nonlinear"), (133, "nonlinear"),
                                        (134, "nonlinear"), (135, "nonlinear"), (136, "nonlinear"),
                                        (137, "linear"), (138, "linear")])
def test_a_correct_model_gets_no_finding(seed, truth):
    _, run = _bench([], seed, truth)
    result = diagnose([run], baseline=truth)
    assert result["findings"] == []
    assert result["best"]["rmse_K"] == pytest.approx(result["baseline"]["rmse_K"])


def _unabsorbed_k(effect: P.Effect, seed: int) -> float:
    """How large an effect is for the baseline: its best in-sample RMSE on a run holding this effect alone.

    Not the raw temperature change: the baseline absorbs part of any effect into its own parameters,
    and what it cannot absorb is what a diagnosis sees.
    """
    _, run = _bench([effect], seed)
    return fit_multistart(model_spec("nonlinear"), [prepare(run, STEP_S)], starts=2).rmse_k


@pytest.mark.parametrize("effects,seed", [([P.gearbox_churning(40.0), P.slip_convection(0.5)], 141),
                                          ([P.heat_split(0.62), P.engine_heat(40.0)], 142)])
def test_two_hidden_effects_are_both_found_the_larger_first(effects, seed):
    _, run = _bench(effects, seed)
    result = diagnose([run], baseline="nonlinear")
    named = [(f["signal"], f["mechanism"]) for f in result["findings"]]
    _accepted_as_documented(result)
    expected = [(e.signal, e.mechanism) for e in effects]
    larger = max(range(2), key=lambda i: _unabsorbed_k(effects[i], seed))
    assert named == [expected[larger], expected[1 - larger]]
    gains = [f["gain_pct"] for f in result["findings"]]
    assert gains == sorted(gains, reverse=True)


def test_two_runs_are_diagnosed_together():
    """Two 40-minute runs of one bench, neither enough alone for many held-out blocks, diagnosed at once."""
    effect = P.gearbox_churning(40.0)
    plant = P.ThermalPlant(paper_params("nonlinear"), [effect])
    runs = [run_schedule(table1_schedule(seed, duration_s=2400), plant, seed=seed) for seed in (171, 172)]
    result = diagnose(runs, baseline="nonlinear")
    assert [(f["signal"], f["mechanism"]) for f in result["findings"]] == [(effect.signal, effect.mechanism)]
    floor = np.sqrt(np.mean([_floor(plant, run) ** 2 for run in runs]))
    assert result["best"]["rmse_K"] < 1.25 * floor
    assert result["findings"][0]["run_gain_pct"] > 50.0  # a real effect carries to the run it was not fitted on



def test_a_run_without_the_optional_channels_is_diagnosed():
    """No load_torque and no individual flywheel sensors (contract: optional): the library leaves them out.
    The first second of clutch speed and torque is missing too, as before a controller's first CAN frame."""
    effect = P.gearbox_churning(50.0)
    _, run = _bench([effect], seed=181)
    run = run.drop(columns=["load_torque", "T_flywheel_1", "T_flywheel_2"])
    run.loc[:99, ["clutch_speed", "clutch_torque"]] = np.nan
    result = diagnose([run], baseline="nonlinear")
    assert [(f["signal"], f["mechanism"]) for f in result["findings"]] == [(effect.signal, effect.mechanism)]
