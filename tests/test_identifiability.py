"""What the runs do not identify (benchlab.identify.identifiability): the criterion on constructed cases, what would
identify a parameter (read from the model file), identify's warnings, the parameter file, the pages and Fig. 3; and
on real fits of the paper's clutch, where the model is exact: a run that never opens the clutch leaves eq. (11)'s
open-clutch law unidentified, a Table 1 run (open at several engine speeds) identifies it."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math

import numpy as np
import pytest

from benchlab.cli import main
from benchlab.identify.api import identify
from benchlab.identify.cooldown import CooldownResult
from benchlab.identify.excitation import what_identifies
from benchlab.identify.fit import FitResult
from benchlab.identify.identifiability import (SAME_COST_CHI2, not_identified, not_identified_lines, recorded,
                                               starts_at_the_minimum)
from benchlab.identify.spec import ModelSpec, ParamSpec
from benchlab.identify.uncertainty import CORRELATION_LIMIT, identifiability_warnings
from benchlab.model.catalog import builtin
from benchlab.model.definition import load_model, parse_model
from benchlab.model.params import load_params, paper_params, save_params
from benchlab.report import resistance as fig3
from benchlab.report.page import params_table
from benchlab.runfile import write_run
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

POSITIVE = ParamSpec("a", 0.3, 1e-4, 20.0)
SIGNED = ParamSpec("b", -1e-3, -1e-2, -1e-5, log=False)


def test_a_value_on_its_bound_is_not_identified():
    reasons = not_identified([POSITIVE, SIGNED], {"a": 1e-4, "b": -1e-5}, {"a": 1e-6, "b": 1e-7})
    assert reasons["a"].startswith("on its lower bound") and reasons["b"].startswith("on its upper bound")


def test_a_standard_error_above_the_value_or_without_effect_is_not_identified():
    errors = {"a": 0.31, "b": 0.0}
    reasons = not_identified([POSITIVE, SIGNED], {"a": 0.3, "b": -1e-3}, errors)
    assert "exceeds its value" in reasons["a"] and "do not depend on it" in reasons["b"]
    assert "do not depend on it" in not_identified([POSITIVE], {"a": 0.3}, {"a": math.nan})["a"]


def test_a_parameter_the_data_pin_is_identified():
    assert not_identified([POSITIVE, SIGNED], {"a": 0.3, "b": -1e-3}, {"a": 0.01, "b": 1e-5},
                          starts=[{"a": 0.29, "b": -1.1e-3}, {"a": 0.32, "b": -0.9e-3}]) == {}


def _fit(costs: list[float], starts: list[dict[str, float]], cost: float, residuals: int) -> FitResult:
    spec = ModelSpec("constructed", None, (POSITIVE, SIGNED))
    return FitResult(spec, {"a": 0.3, "b": -1e-3}, cost, 0.1, residuals, np.zeros((residuals, 2)),
                     np.zeros(residuals), starts=len(costs), start_costs=costs, start_params=starts)


def test_starts_at_one_cost_far_apart_are_not_identified_and_starts_higher_up_do_not_count():
    variance = 100.0 / (102 - 2)  # cost / (residuals - parameters)
    costs = [100.0, 100.0 + 0.9 * SAME_COST_CHI2 * variance, 100.0 + 2 * SAME_COST_CHI2 * variance]
    ends = [{"a": 0.3, "b": -1e-3}, {"a": 0.01, "b": -1.05e-3}, {"a": 15.0, "b": -8e-3}]
    same = starts_at_the_minimum(_fit(costs, ends, 100.0, 102))
    assert same == ends[:2]
    reasons = not_identified([POSITIVE, SIGNED], {"a": 0.3, "b": -1e-3}, {"a": 0.01, "b": 1e-5}, starts=same)
    assert list(reasons) == ["a"] and "0.01 to 0.3" in reasons["a"] and "same cost" in reasons["a"]


def test_what_identifies_a_parameter_is_read_from_the_model_file():
    clutch = builtin("nonlinear")
    for name in ("a2", "b2"):
        needs = what_identifies(clutch, name)
        assert "long cool-downs" in needs and "engine_speed" in needs and "the clutch open" in needs
        assert "benchlab run cooldown-sweep" in needs
    assert "the clutch clamped" in what_identifies(clutch, "a1")
    assert "sensor on node P" in what_identifies(clutch, "C_P")
    motor = load_model("examples/ipmsm.toml")  # not the bench's channels: no clutch protocol suggested
    assert all("benchlab run" not in what_identifies(motor, name) for name in motor.parameters)
    assert "speed" in what_identifies(motor, "q_R")
    hot = parse_model({"schema": "benchlab-model/1", "nodes": {"N": "C"}, "boundaries": {"amb": "T_ambient"},
                       "links": [{"name": "L", "between": ["N", "amb"],
                                  "resistance": "where(load_torque > 100, R1, R2*exp(k*engine_speed))"}],
                       "outputs": {"T_air": "N"},
                       "parameters": {"C": {"start": 1, "min": 0.1, "max": 10}, "R1": {"start": 1, "min": 0.1,
                                      "max": 10}, "R2": {"start": 1, "min": 0.1, "max": 10},
                                      "k": {"start": -1e-3, "min": -1, "max": 0}}}, "constructed.toml")
    assert what_identifies(hot, "R1").startswith("runs with long cool-downs with load_torque > 100")
    assert "several values of engine_speed with load_torque <= 100" in what_identifies(hot, "k")


def test_a_standard_error_at_rounding_level_is_no_standard_error():
    """A parameter the channels do not depend on gets a covariance of rounding size from the pseudo-inverse (a
    switch's band the runs never cross: 1.9e-17 on 9.55 K): not identified, like an error of exactly zero; a
    small but real error is kept."""
    from benchlab.identify.identifiability import not_identified
    from benchlab.identify.spec import ParamSpec

    band = ParamSpec("band", 1.0, 0.0, 9.6, log=False)
    assert "do not depend on it" in not_identified([band], {"band": 9.552}, {"band": 1.93e-17})["band"]
    assert not_identified([band], {"band": 9.552}, {"band": 1e-6}) == {}


def test_warnings_group_close_pairs_and_say_no_infinite_correlation():
    names = ["x", "y", "z", "w", "v"]
    errors = np.array([0.1, 0.2, 0.3, 0.0, 0.1])
    corr = np.eye(5)
    corr[0, 1] = corr[1, 0] = 0.97
    corr[1, 2] = corr[2, 1] = -0.96
    corr[3, :] = corr[:, 3] = np.inf  # a zero standard error divided into a covariance
    corr[3, 3] = np.nan
    reasons = {"w": "the measured channels do not depend on it (no standard error)",
               "v": "standard error 2 exceeds its value 1"}
    warnings = identifiability_warnings(names, [1.0, 2.0, 3.0, 4.0, 1.0], errors, corr, [1.0] * 5, reasons)
    assert warnings[:2] == not_identified_lines(reasons)
    assert not any("inf" in w for w in warnings)
    close = [w for w in warnings if "hard to tell apart" in w]
    assert close == [f"x, y and z are hard to tell apart (2 of their 3 pairs correlate beyond ±{CORRELATION_LIMIT:g}; "
                     "strongest x and y, +0.970)"]
    assert not any(w.startswith("v is poorly") for w in warnings)  # said once, as not identified


def test_the_page_shows_why_instead_of_a_standard_error(tmp_path):
    params = paper_params("nonlinear")
    params.extra = {"uncertainty": {name: 0.01 * abs(value) for name, value in params.items()} | {"a2": 90.0,
                                                                                                   "b2": 0.0}}
    found = recorded(params)  # a file without "not_identified": from its standard errors and bounds
    assert set(found) == {"a2", "b2"} and "clutch open" in found["a2"]
    path = tmp_path / "p.json"
    save_params(path, params, {"not_identified": found})
    again = load_params(path)
    assert recorded(again) == found
    rows = {line.split("|")[1].strip(): line for line in params_table([("nonlinear", again)]).splitlines()[2:]}
    assert "not identified: standard error 90" in rows["`a2`"] and "± 90" not in rows["`a2`"]
    assert "not identified" not in rows["`a1`"]


def test_the_job_page_says_what_is_not_identified(tmp_path):
    from benchlab.report.index import _not_identified_section, _truth_section

    params = paper_params("nonlinear")
    errors = {name: 0.01 * abs(value) for name, value in params.items()}
    params.extra = {"uncertainty": errors, "not_identified": {"a2": "standard error 90 exceeds its value 0.45"}}
    truth = {name: 1.01 * value for name, value in params.items()}
    rows = {row.split("</td>")[0]: row for row in _truth_section(params, truth, errors).split("<tr>")[2:]}
    assert "not identified: standard error 90" in rows["<td><code>a2</code>"]
    assert "not identified" not in rows["<td><code>a1</code>"] and "1.0" in rows["<td><code>a1</code>"]
    assert "<code>a2</code> = 0.45: standard error 90" in _not_identified_section(params)
    params.extra["not_identified"] = {}
    assert _not_identified_section(params) == ""


def test_the_batch_table_names_what_is_not_identified_and_gives_it_no_standard_error():
    from types import SimpleNamespace

    from benchlab.batch import adapter
    from benchlab.batch.tasks import parameter_columns
    from benchlab.identify.uncertainty import Uncertainty

    reasons = {"a2": "standard error 90 exceeds its value 0.45"}
    u = Uncertainty(["a1", "a2"], {"a1": 0.01, "a2": 90.0}, np.eye(2), {}, [1], not_identified_lines(reasons),
                    reasons)
    result = SimpleNamespace(params={"a1": 0.35, "a2": 0.45}, uncertainty=u, fitting={"r": {"rmse_K": 0.1,
                                                                                              "nrmse_pct": 1.0}})
    columns = parameter_columns(*adapter.fitted(result))
    assert columns["a1_se"] == 0.01 and math.isnan(columns["a2_se"]) and columns["a2"] == 0.45
    assert adapter.fit_figures(result)["not_identified"] == "a2"


def _cooldown(speed: float, state: int, r: float) -> CooldownResult:
    return CooldownResult(0, speed, state, 0.0, 0.0, 1.0, r, 0.01, 0.02, 60.0, 0.1, 0.05, 100, 1.0)


def test_fig3_y_range_from_the_points_and_curves_not_from_a_band(tmp_path, monkeypatch):
    params = paper_params("nonlinear")
    params.extra = {"uncertainty": {"R0": 0.01, "a1": 0.01, "b1": 1e-5, "a2": 90.0, "b2": 1e-5},
                    "not_identified": {"a2": "standard error 90 exceeds its value 0.45"}}
    points = [_cooldown(1000.0, 1, 0.53), _cooldown(2500.0, 0, 0.14)]
    figures = []
    monkeypatch.setattr(fig3, "save", lambda fig, path: figures.append(fig) or path)
    fig3.plot_resistance([("nonlinear", params)], points, tmp_path / "fig3.png")
    ax = figures[0].axes[0]
    speed = np.linspace(0.0, fig3.SPEED_MAX_RPM, 301)
    curves = [fig3.resistance(params, speed, state)[0] for state in (0, 1)]
    highest = max([float(np.max(c)) for c in curves] + [p.R + p.R_u for p in points])
    assert ax.get_ylim() == (0.0, pytest.approx(1.1 * highest))
    legend = [t.get_text() for t in figures[0].legends[0].get_texts()]
    assert any("clutch open (S = 0): ±2 SE band left out (a2 not identified" in t for t in legend)
    assert any("clutch closed (S = 1) ±2 SE" in t for t in legend)


def _table1(never_open: bool):
    """A 20-minute Table 1 run of the paper's clutch; `never_open`: its open halves of the cool-downs driven clamped
    instead, so the clutch is never open."""
    steps = table1_schedule(7, duration_s=1200)
    if never_open:
        steps = tuple(dataclasses.replace(s, phase="drive", clutch_torque_nm=45.0) if s.phase == "open" else s
                      for s in steps)
    return run_schedule(steps, ThermalPlant(), seed=7)


@pytest.fixture(scope="module")
def never_open(tmp_path_factory):
    """`benchlab identify` of a run whose clutch is never open: what it printed and the parameter file."""
    run = _table1(never_open=True)
    assert not np.any(run["clutch_state"].to_numpy() < 0.5)
    folder = tmp_path_factory.mktemp("never_open")
    write_run(folder / "run.h5", run, run.attrs["dt"], protocol="table1")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["identify", str(folder / "run.h5"), "--out", str(folder / "p.json"), "--starts", "4", "-q"]) == 0
    return printed.getvalue(), folder / "p.json"


def test_a_run_that_never_opens_the_clutch_leaves_the_open_law_unidentified(never_open):
    printed, path = never_open
    doc = json.loads(path.read_text())
    assert {"a2", "b2"} <= set(doc["not_identified"])
    assert all("the clutch open" in doc["not_identified"][name] for name in ("a2", "b2"))
    assert not any("inf" in w for w in doc["warnings"])
    assert doc["warnings"][:len(doc["not_identified"])] == not_identified_lines(doc["not_identified"])
    assert recorded(load_params(path)) == doc["not_identified"]
    lines = printed.splitlines()
    first_error = next(i for i, line in enumerate(lines) if "±" in line)
    for name in doc["not_identified"]:
        line = next(i for i, line in enumerate(lines) if line.split()[0] == name)
        assert line < first_error and "not identified" in lines[line] and "±" not in lines[line]


def test_a_table1_run_identifies_the_open_law():
    result = identify([_table1(never_open=False)], "nonlinear", starts=4)
    assert result.uncertainty.not_identified == {}  # the model is exact and the run excites every parameter
    assert result.summary()["not_identified"] == result.uncertainty.not_identified
    assert not any("inf" in w for w in result.uncertainty.warnings)


def test_identified_by_runs_names_the_run_that_carries_each_parameter():
    """Two runs of a linear problem y = J θ + noise: `a` and `b` enter run 1 only as a + b and run 2 only as a − b
    (neither run alone separates them, both together do), `c` is seen by run 1 alone, `d` by neither run."""
    from types import SimpleNamespace

    from benchlab.identify.spec import ParamSpec
    from benchlab.identify.uncertainty import identified_by_runs

    rng = np.random.default_rng(3)
    steps = 400
    t = np.linspace(0.0, 1.0, steps)
    rows = {0: np.column_stack([np.ones(steps), np.ones(steps), np.sin(7 * t), np.zeros(steps)]),
            1: np.column_stack([np.ones(steps), -np.ones(steps), np.zeros(steps), np.zeros(steps)])}
    jacobian = np.vstack([rows[0], rows[1]])
    residuals = 0.1 * rng.standard_normal(2 * steps)
    names = ("a", "b", "c", "d")
    specs = [ParamSpec(n, 1.0, 1e-3, 1e3) for n in names]
    result = SimpleNamespace(jacobian=jacobian, residuals=residuals, free_names=list(names),
                             params=dict.fromkeys(names, 1.0), spec=SimpleNamespace(free=specs))
    datasets = [_Run(steps) for _ in range(2)]
    pinned = identified_by_runs(result, datasets, ["run1", "run2"])
    assert pinned == {"a": ["together"], "b": ["together"], "c": ["run1"], "d": []}


class _Run:
    """The part of a FitData that the run split reads: its fitting steps and which step each residual belongs to."""

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.fitted = {"T": (np.arange(steps), None)}

    def __len__(self) -> int:
        return self.steps
