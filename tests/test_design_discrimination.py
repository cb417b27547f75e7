"""`benchlab design --diagnosis`: the T-optimal run between two extensions of a diagnosis, refitted to the session's
20-min Table 1 run; its expected outcome printed, its schedule within the bench's limits, and more telling than a
Table 1 run of the same length under the same two models."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchlab.cli import main
from benchlab.design.discrimination import differences, noncentrality
from benchlab.design.rivals import contest, refitted_rivals
from benchlab.identify.fit import simulate_outputs
from benchlab.runner.session import RunRequest, bench_config
from protocols.limits import schedule_problems
from protocols.table1 import table1_schedule

#: Two explanations of the paper's speed-dependent convection (eq. 10-11) as diagnose's library names them.
FAVOURED, OTHER = "speed_convection", "engine_speed_linear_R_PA_R_FA"


def tied(favoured: str = FAVOURED, other: str | None = OTHER) -> dict:
    """A diagnosis of the linear model with one finding, tied with `other` where given."""
    alternatives = [{"candidate": other}] if other else []
    return {"baseline": {"model": "linear"},
            "findings": [{"candidate": favoured, "round": 1, "alternatives": alternatives}]}


def test_contest_is_the_tie_else_the_cause_against_its_parent():
    doc = {"baseline": {"model": "linear"},
           "findings": [{"candidate": "a", "round": 1, "alternatives": []},
                        {"candidate": "b", "round": 2, "alternatives": [{"candidate": "c"}]}]}
    found = contest(doc, "d.json")
    assert (found.parent, found.favoured, found.other) == (("a",), "b", "c")
    alone = contest(tied(other=None), "d.json")
    assert (alone.parent, alone.favoured, alone.other) == ((), FAVOURED, None)


def test_a_tie_with_a_law_of_a_temperatures_level_is_rebuilt(short_run, monkeypatch):
    """A rival that diagnose names among its level laws (a thermostat's fan on the housing) is rebuilt from the
    library as diagnose built it, every key resolved before the first fit; a key no library holds is one line."""
    import benchlab.design.rivals as rivals
    from benchlab.errors import InputError

    class Resolved(Exception):
        pass

    def resolved(*args, **kwargs):
        raise Resolved
    monkeypatch.setattr(rivals, "fit_multistart", resolved)
    with pytest.raises(Resolved):
        refitted_rivals(tied(FAVOURED, "level_T_housing_latch_R_AT"), "d.json", [short_run])
    with pytest.raises(InputError, match="an extension of linear on these runs, got 'level_T_nowhere_latch_R_AT'"):
        refitted_rivals(tied(FAVOURED, "level_T_nowhere_latch_R_AT"), "d.json", [short_run])


def test_a_diagnosis_without_findings_is_one_line(refused, run_file, tmp_path):
    path = tmp_path / "d.json"
    path.write_text(json.dumps({"baseline": {"model": "linear"}, "findings": [], "leads": []}))
    refused(["design", str(run_file), "--diagnosis", str(path), "--out", str(tmp_path / "plan.json")],
            "findings", "nothing is left open")


def test_designed_run_tells_the_rivals_apart_better_than_table1(run_file, short_run, tmp_path, capsys):
    path, out = tmp_path / "d.json", tmp_path / "plan.json"
    path.write_text(json.dumps(tied()))
    assert main(["design", str(run_file), "--diagnosis", str(path), "--out", str(out), "--budget", "15"]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["kind"] == "discrimination" and doc["planned_min"] <= 15
    expected = doc["expected"]
    assert (expected["favoured"], expected["loser"]) == (FAVOURED, OTHER)
    assert expected["rmse_gap_K"] > 0 and f"expected: {OTHER}" in printed
    limits = bench_config(RunRequest(protocol="design", out=out, bench="sim")).limits
    from protocols.schedule import steps_from_rows

    steps = steps_from_rows(doc["schedule"], str(out))
    assert not schedule_problems(steps, limits)
    # the same two models, refitted the same way, on a Table 1 run of the plan's length: less to tell them apart
    favoured, other, runs = refitted_rivals(tied(), "d.json", [short_run])
    peer = table1_schedule(11, duration_s=doc["planned_min"] * 60)
    ambient = doc["ambient_C"]
    rho = min(favoured.rho, other.rho)
    peer_statistic = noncentrality(differences(favoured, other, peer, ambient, limits), expected["misfit_K"], rho)
    assert expected["statistic"] > peer_statistic
    # the runs so far: the same statistic on them (what they already tell apart), not the design's criterion
    so_far = sum(noncentrality({c: simulate_outputs(favoured.network, favoured.params, d)[c]
                                - simulate_outputs(other.network, other.params, d)[c] for c in d.targets},
                               expected["misfit_K"], rho) for d in runs)
    assert expected["statistic_now"] == pytest.approx(so_far, rel=1e-6)
    # every place both models have is ranked, the plate (unmeasured) by what it removes of its own variance
    assert {s["channel"] for s in doc["sensors"]} >= {"T_pressure_plate", "T_flywheel", "T_air", "T_housing"}
    assert all(s["test_gain"] is not None and s["test_gain"] >= 0 for s in doc["sensors"])
    assert "test statistic +" in printed


def test_diagnose_page_names_each_tie_and_the_design_that_settles_it():
    from benchlab.diagnose.page import _added

    finding = {"candidate": FAVOURED, "summary": "s", "signal": "engine_speed", "mechanism": "m", "extension": "e",
               "params": {}, "units": {}, "label": "cause", "label_reasons": [],
               "alternatives": [{"candidate": OTHER, "gain_pct": 12.0, "tell_apart_by": "a sensor on node P"}]}
    summary = {"method": {"baseline_bounds": []}, "findings": [finding], "leads": [],
               "floor": {"noise_K": 0.01, "baseline_ratio": 9.0, "best_ratio": 2.0, "verdict": "v"}}
    page = "\n".join(_added(summary))
    assert OTHER in page and "a sensor on node P" in page and "--diagnosis" in page
    finding["alternatives"] = []
    assert "--diagnosis" not in "\n".join(_added(summary))


def test_forecast_names_no_loser_between_one_model_and_itself(short_run, tmp_path):
    """The forecast simulates the run by the favoured model with its misfit as noise and refits the other with it:
    where the other is the same model (the plant's own), it absorbs nothing and is not beaten; its RMSE within a
    tenth of the noise of the favoured's."""
    from benchlab.design.blocks import candidate_blocks, numbered
    from benchlab.design.discrimination import Rival, forecast, misfit
    from benchlab.diagnose.engine import ALPHA, STEP_S, diagnosed_spec
    from benchlab.identify.data import prepare
    from benchlab.model.build import build_spec
    from benchlab.model.catalog import resolve_model
    from benchlab.model.params import paper_params

    model = resolve_model("nonlinear")
    runs = [prepare(short_run, STEP_S, name="0", network=build_spec(model).network)]
    spec = diagnosed_spec(model, runs)
    params = {**{p.name: p.initial for p in spec.free}, **dict(paper_params("nonlinear").items())}
    plant = Rival("nonlinear", spec, params, *misfit(spec.network, params, runs))
    limits = bench_config(RunRequest(protocol="design", out=tmp_path / "plan.json", bench="sim")).limits
    block = min(candidate_blocks(limits), key=lambda b: b.expected_s)
    steps = numbered([block] * 3)
    expected = forecast(plant, plant, steps, runs, float(short_run["T_ambient"].mean()), limits)
    assert expected.blocks >= 3 and expected.block_p >= ALPHA
    assert abs(expected.rmse_gap) < 0.1 * max(plant.rmse.values())


def test_the_criterion_counts_only_what_the_refitted_model_cannot_absorb():
    """T-criterion with the refit: a difference the rival's parameters can follow is absorbed (up to what the runs so
    far hold them to), one they cannot follow counts whole, and a block chosen twice gains less the second time."""
    from benchlab.design.discrimination import Misfit

    rng = np.random.default_rng(3)
    jac = rng.standard_normal((200, 2))
    follows = jac @ np.array([0.5, -1.0])  # what a change of the rival's two parameters does
    beyond = rng.standard_normal(200)
    beyond -= jac @ np.linalg.lstsq(jac, beyond, rcond=None)[0]  # what no change of them does
    loose, held = 1e-9 * np.eye(2), 1e6 * np.eye(2)
    assert Misfit([follows], [jac], loose).left([0]) == pytest.approx(0.0, abs=1e-6)
    assert Misfit([follows], [jac], held).left([0]) == pytest.approx(follows @ follows, rel=1e-3)
    assert Misfit([beyond], [jac], loose).left([0]) == pytest.approx(beyond @ beyond, rel=1e-9)
    partly = Misfit([follows + beyond], [jac], 10.0 * np.eye(2))
    first, both = partly.left([0]), partly.left([0, 0])
    assert 0 < both - first < first
