"""`benchlab design`: plans within the bench's limits and budget, Fisher ranking where the answer is known, the
expected outcome printed, `benchlab run PLAN.json` reading the plan. Uses the session's 20-min Table 1 run."""

from __future__ import annotations

import json

import pytest

from benchlab.cli import main
from benchlab.commands.run import design_plan
from benchlab.design import fisher
from benchlab.design.blocks import candidate_blocks
from benchlab.model.catalog import model_spec
from benchlab.model.params import paper_params, save_params
from benchlab.runner.session import RunRequest, plan
from protocols.limits import BenchLimits, schedule_problems


@pytest.fixture()
def open_params(tmp_path):
    """The paper's parameters, with a2 and b2 (the open clutch's law, eq. 11) recorded as not identified."""
    path = tmp_path / "p.json"
    params = paper_params("nonlinear")
    save_params(path, params, {"not_identified": {"a2": "no effect", "b2": "no effect"},
                               "uncertainty": {k: 0.02 * abs(v) for k, v in params.items()}})
    return path


def test_budget_too_short_is_one_line(refused, run_file, open_params, tmp_path):
    refused(["design", str(run_file), "--params", str(open_params), "--out", str(tmp_path / "plan.json"),
             "--budget", "2"], "--budget", "shortest block")


def test_a_model_with_a_switch_is_one_line(refused, run_file, tmp_path):
    """A model file with hysteresis(...) cannot be predicted chunk by chunk yet: bad input, not a crash."""
    from test_level_laws import _switched_model

    from benchlab.model.params import ModelParams

    path = tmp_path / "switched.json"
    save_params(path, ModelParams(_switched_model(), {"C": 100.0, "R": 0.5, "q": 40.0, "on": 31.0, "off": 29.0}),
                {"not_identified": {"q": "no effect"}})
    refused(["design", str(run_file), "--params", str(path), "--out", str(tmp_path / "plan.json")],
            "switched.json", "model", "hysteresis", "heater")


def test_every_block_passes_the_limits_and_a_tighter_bench_is_kept():
    tight = BenchLimits(max_engine_speed_rpm=1800.0, max_slip_energy_j=40e3)
    for limits in (BenchLimits(), tight):
        blocks = candidate_blocks(limits)
        assert blocks
        for block in blocks:
            assert not schedule_problems(block.steps, limits), block.name
            assert max(s.engine_speed_rpm for s in block.steps) <= limits.max_engine_speed_rpm


def test_open_clutch_law_is_informed_by_open_clutch_cooldowns_only():
    """a2 enters R_FA and R_PA only while the clutch is open: a clamped cool-down carries no information on it, an
    open one does (analytically zero against positive)."""
    params = paper_params("nonlinear")
    spec = model_spec(params.definition)
    names = [p.name for p in spec.free]
    limits = BenchLimits()
    noise = {"T_flywheel": 0.02, "T_air": 0.01, "T_housing": 0.01}
    by_name = {b.name: b for b in candidate_blocks(limits)}
    info = {}
    for state in ("open", "clamped"):
        block = by_name[f"heat, cool 600 s at 1500 rpm clutch {state}"]
        data = fisher.predicted_data(block.steps, params, spec.network, 22.0, limits.drivetrain)
        info[state] = fisher.information(spec.network, params, ["a2", "a1"], [data], noise)
    assert info["open"][0, 0] > 100 * info["clamped"][0, 0]
    assert info["clamped"][1, 1] > info["open"][1, 1]


def test_design_prints_the_expected_outcome_and_run_reads_the_plan(run_file, open_params, tmp_path, capsys):
    out = tmp_path / "plan.json"
    assert main(["design", str(run_file), "--params", str(open_params), "--out", str(out), "--budget", "15"]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["schema"] == "benchlab-plan/1" and doc["planned_min"] <= 15
    for name in ("a2", "b2"):
        expected = doc["expected"][name]
        assert expected["relative_error_expected"] < expected["relative_error_now"]
        assert f"{name}: " in printed and f"{100 * expected['relative_error_expected']:.1f} %" in printed
    assert any("clutch open" in block for block in doc["blocks"])
    # a sensor on the plate itself removes the most of the plate's estimate variance (it reads that state)
    assert doc["sensors"][0]["channel"] == "T_pressure_plate" and not doc["sensors"][0]["measured"]
    assert "T_pressure_plate (node P, no sensor now)" in printed
    scheduled, recorded = design_plan(str(out))
    steps, config, options = plan(RunRequest(protocol="design", out=tmp_path / "r.h5", steps=scheduled,
                                             options=recorded))
    assert options["expected"] == doc["expected"]
    assert not schedule_problems(steps, config.limits)
    assert main(["run", str(out), "--bench", "sim", "--dry-run"]) == 0
    assert "design" in capsys.readouterr().out


def test_residual_structure_is_said_against_the_expected_outcome():
    from benchlab.design.command import model_error_warnings

    white = {"white": True, "structure_K": 0.001}
    assert model_error_warnings({"residuals": {"r.h5": {"T_air": white}}}) == []
    lines = model_error_warnings({"residuals": {"r.h5": {"T_air": white,
                                                         "T_flywheel": {"white": False, "structure_K": 0.186}}}})
    assert len(lines) == 1 and "0.186 K" in lines[0] and "T_flywheel of r.h5" in lines[0]


def test_open_branch_alone_is_fitted_from_its_points_with_the_covariance_error():
    """A designed run's cool-downs may all have the clutch open: eq. (11)'s open branch and R0 from them alone, the
    clamped branch left out; the standard errors follow the points' (twice the noise, twice the error)."""
    import numpy as np

    from benchlab.identify.cooldown import CooldownResult, fit_eq11

    def points(se_share):
        rows = []
        for rpm in (500.0, 1000.0, 1500.0, 2000.0, 2500.0):
            r = 0.4 * np.exp(-0.0012 * rpm) + 0.03
            rows.append(CooldownResult(-1, rpm, 0, rpm, 0.0, 300.0, r, se_share * r, np.nan, np.nan, np.nan,
                                       np.nan, 300, 1.0))
        return rows

    with pytest.raises(ValueError):
        fit_eq11(points(0.01))  # the full law needs both clutch states
    eq11 = fit_eq11(points(0.01), partial=True)
    assert "a1" not in eq11 and "b1" not in eq11
    assert eq11["a2"] == pytest.approx(0.4, rel=1e-4) and eq11["b2"] == pytest.approx(-0.0012, rel=1e-4)
    assert eq11["a2_se"] > 0 and fit_eq11(points(0.02), partial=True)["a2_se"] == pytest.approx(2 * eq11["a2_se"],
                                                                                                rel=1e-3)


def test_points_scattered_beyond_their_errors_carry_the_between_reading_scatter():
    """Readings that scatter about eq. (11) by a share of R far beyond their own errors (the run's history, not
    noise): the fit estimates that share (Paule-Mandel: the reduced chi-square brought to 1) and its standard errors
    grow with it; points within their errors carry none, and points that leave no degree of freedom say nothing."""
    import numpy as np

    from benchlab.identify.cooldown import CooldownResult, fit_eq11

    def points(share, se_share=0.005, speeds=(500.0, 1000.0, 1500.0, 2000.0, 2500.0) * 2):
        rng = np.random.default_rng(7)
        rows = []
        for rpm in speeds:
            r = (0.4 * np.exp(-0.0012 * rpm) + 0.03) * (1.0 + share * rng.standard_normal())
            rows.append(CooldownResult(-1, rpm, 0, rpm, 0.0, 300.0, r, se_share * r, np.nan, np.nan, np.nan,
                                       np.nan, 300, 1.0))
        return rows

    small, large = fit_eq11(points(0.05), partial=True), fit_eq11(points(0.10), partial=True)
    assert 0.025 < small["scatter"] < 0.1 and large["scatter"] == pytest.approx(2 * small["scatter"], rel=0.05)
    assert large["a2_se"] == pytest.approx(2 * small["a2_se"], rel=0.2)
    assert fit_eq11(points(0.0), partial=True)["scatter"] == 0.0
    assert "scatter" not in fit_eq11(points(0.05, speeds=(500.0, 1500.0, 2500.0)), partial=True)


def test_a_repeated_point_is_read_first_and_last():
    """A point the reading's design takes twice spans the run (the history that moves a reading then shows in the
    points' scatter); the other blocks keep their order, and a plan without a repeat stays as chosen."""
    from benchlab.design.precision import repeats_apart

    speed = {0: 1000, 1: 2000, 2: 500, 3: 500, 4: 1500}.__getitem__
    assert repeats_apart([0, 1, 2, 3], speed) == [2, 0, 1, 3]
    assert repeats_apart([0, 1, 4], speed) == [0, 1, 4]


def test_a_fixed_length_cooldown_is_complete_and_a_timed_out_condition_is_not():
    from benchlab.identify.cooldown import completed
    from benchlab.runfile.read import Event
    from protocols.schedule import Condition, Step

    fixed = Step("open", 300.0, 1500.0, 0.0, 0.0, 0, label="cooldown")
    conditional = Step("open", 3600.0, 1500.0, 0.0, 0.0, 0, label="cooldown",
                       until=(Condition("T_flywheel", "<=", 60.0),))
    end = lambda step, reason: Event(300.0, 0, "cooldown_end", "", step, reason)  # noqa: E731
    assert completed(end(0, "time"), [fixed])
    assert not completed(end(0, "time"), [conditional])
    assert completed(end(0, "condition"), [conditional])


def test_eq11_alone_is_designed_for_the_cooldown_reading(run_file, open_params, tmp_path, capsys, refused):
    """Designed for a2 and b2 alone for the reading, the plan is the cool-down sweep's cycles (docs/design.md): each
    cool-down follows a heat-up until the flywheel is steady, within the bench's limits; open-clutch cool-downs at
    three engine speeds at least (the open branch's a2, b2 and R0) and one more (a degree of freedom to show the
    readings' scatter), the expected errors those of that reading. A budget shorter than one such cycle is one
    line, exit 2."""
    from protocols.limits import schedule_problems
    from protocols.schedule import step_from_dict

    out = tmp_path / "plan.json"
    assert main(["design", str(run_file), "--params", str(open_params), "--out", str(out), "--budget", "70",
                 "--reading"]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["identification"] == "cooldowns" and doc["planned_min"] <= 70
    assert "each read on its own" in printed and doc["scatter"] >= 0
    steps = [step_from_dict(row) for row in doc["schedule"]]
    assert not schedule_problems(steps, BenchLimits())
    cycles = sorted({s.cycle for s in steps})
    for cycle in cycles:
        own = [s for s in steps if s.cycle == cycle]
        assert own[0].phase == "heat" and own[0].until[0].op == "steady" and own[-1].label == "cooldown"
    read = [s for s in steps if s.label == "cooldown" and dict(s.point)["clutch_state"] == 0.0]
    assert len({s.engine_speed_rpm for s in read}) >= 3 and len(read) >= 4
    for name in ("a2", "b2"):
        assert 0 < doc["expected"][name]["relative_error_expected"] < 1
    refused(["design", str(run_file), "--params", str(open_params), "--out", str(tmp_path / "short.json"),
             "--budget", "5", "--reading"], "--budget", "shortest block")


def test_a_steady_block_is_predicted_as_the_runner_plays_it():
    """A steady block's closed-loop steps predicted on the model (`fisher.open_loop`, `protocols.estimates.played`):
    heat pulses until the flywheel is steady at the sweep's 70 degC, then a cool-down that ends where the flywheel
    reads 60 degC."""
    import numpy as np

    from benchlab.design.blocks import steady_blocks
    from benchlab.network.plant import NetworkPlant

    params = paper_params("nonlinear")
    spec = model_spec(params.definition)
    limits = BenchLimits()
    block = steady_blocks(limits, NetworkPlant(spec.network, params))[0]
    steps = fisher.open_loop(block.steps, params, spec.network, 22.0)
    assert not any(s.until or s.phase == "heat" for s in steps)
    pulses = [s for s in steps if s.phase == "launch" and s.label == "heat"]
    heated_s = sum(s.duration_s for s in steps if s.label == "heat")
    assert len(pulses) > 5 and heated_s < 0.5 * block.steps[0].duration_s  # ended by the steady test, not timed out
    run = fisher.predicted_run(steps, params, spec.network, 22.0, limits.drivetrain)
    flywheel, time = run["T_flywheel"].to_numpy(), run["time"].to_numpy()
    cooled_from = time[-1] - steps[-1].duration_s
    assert np.mean(flywheel[(time > cooled_from - 60) & (time <= cooled_from)]) == pytest.approx(70.0, abs=1.5)
    assert flywheel[-1] == pytest.approx(60.0, abs=0.5)
