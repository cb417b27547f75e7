"""diagnose --validate: each finding's gain measured on runs no fit saw, and a finding named as a cause only where its
added parameters are identified and its gain carries to those runs (docs/diagnose.md, steps 12-13)."""

from __future__ import annotations

import json
import pytest

from benchlab.cli import main
from benchlab.diagnose.engine import (STEP_S, Finding, _causes, _held_out, block_test, diagnosed_spec,
                                      extended_spec)
from benchlab.diagnose.library import candidates
from benchlab.identify.data import prepare
from benchlab.identify.fit import fit
from benchlab.model.build import build_spec
from benchlab.model.catalog import resolve_model
from benchlab.model.params import paper_params
from benchlab.runfile import ALIGNED_UNITS, write_run
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

RUN_S = 2400.0  # 40 min: four 600 s folds, eight 300 s blocks for the block test
#: in-run and unseen gains of a right extension: both are 1 - floor/baseline up to the parameter noise of the fits
#: and the two runs' different schedules (tests/test_diagnose.py allows 10 points against the truth's gain)
GAIN_AGREEMENT_PCT = 10.0


def _run_file(tmp_path, name: str, effects, seed: int):
    """A RUN_S Table 1 run of the paper's nonlinear clutch plus `effects`, as a run file."""
    plant = P.ThermalPlant(paper_params("nonlinear"), effects)
    run = run_schedule(table1_schedule(seed, duration_s=RUN_S), plant, seed=seed)
    path = tmp_path / name
    write_run(path, run, run.attrs["dt"], protocol="table1")
    return path, run


def _diagnose_json(capsys, *args: str) -> dict:
    capsys.readouterr()
    assert main(["diagnose", *args, "--baseline", "nonlinear", "--json", "-q"]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_right_extension_carries_to_an_unseen_run(tmp_path, capsys):
    """An engine-side heat source the model lacks, diagnosed on one run and validated on a run of another schedule:
    the named source gains on the unseen run about what it gains held out, and is a cause."""
    effect = P.engine_heat(50.0)
    fitted, _ = _run_file(tmp_path, "fit.h5", [effect], 341)
    unseen, _ = _run_file(tmp_path, "unseen.h5", [effect], 342)
    result = _diagnose_json(capsys, str(fitted), "--validate", str(unseen))
    assert result["findings"], result["leads"]
    first = result["findings"][0]
    assert (first["signal"], first["mechanism"]) == ("engine_speed", "heat_source"), first
    assert first["unseen_gain_pct"] > 0 and first["not_identified"] == {}
    assert abs(first["unseen_gain_pct"] - first["gain_pct"]) < GAIN_AGREEMENT_PCT, first
    assert first["unseen"]["rmse_after_K"] < first["unseen"]["rmse_before_K"]
    assert [r["run"] for r in first["unseen"]["runs"]] == [0]
    assert result["best"]["unseen_gain_pct"] > 0 and result["leads"] == []


def test_without_validate_the_keys_are_there_and_empty(tmp_path, capsys):
    path, _ = _run_file(tmp_path, "fit.h5", [P.engine_heat(50.0)], 343)
    result = _diagnose_json(capsys, str(path))
    assert result["findings"] and result["leads"] == []
    for entry in (*result["findings"], result["best"]):
        assert entry["unseen_gain_pct"] is None and entry["unseen"] is None
    assert {"unseen", "causes"} <= set(result["method"])


def test_a_gain_that_does_not_carry_is_a_lead(tmp_path, capsys):
    """The effect is in the diagnosed run only: the extension is right for that run, the unseen run (the same clutch
    without it) gets worse with it, so it is a lead with the reason, not a cause."""
    effect = P.engine_heat(50.0)
    fitted, _ = _run_file(tmp_path, "fit.h5", [effect], 344)
    unseen, _ = _run_file(tmp_path, "unseen.h5", [], 345)
    result = _diagnose_json(capsys, str(fitted), "--validate", str(unseen))
    assert result["findings"] == []
    lead = result["leads"][0]
    assert (lead["signal"], lead["mechanism"]) == ("engine_speed", "heat_source")
    assert lead["unseen_gain_pct"] < 0 and "does not carry" in lead["reasons"][0]
    assert lead["label"] == ("patch" if result["floor"]["beyond_library"] else "lead"), lead["label_reasons"]
    assert result["best"]["model"] == "nonlinear"


def test_a_finding_whose_added_parameter_is_not_identified_is_a_lead():
    """A lag on the air sensor added to a correct model (the plant's air sensor has none): the fit drives its time
    constant towards nothing, where its standard error exceeds it. Whatever its gain, it is a lead naming that
    parameter, and the model is the baseline again."""
    plant = P.ThermalPlant(paper_params("nonlinear"))
    run = run_schedule(table1_schedule(346, duration_s=RUN_S), plant, seed=346)
    model = resolve_model("nonlinear")
    data = [prepare(run, STEP_S, name="0", network=build_spec(model).network)]
    base_spec = diagnosed_spec(model, data)
    base = fit(base_spec, data, start={p.name: p.initial for p in base_spec.free})
    base_held = _held_out(base.spec, base.params, data)
    channels = dict(data[0].channels)
    lag = next(c for c in candidates(model, channels, ALIGNED_UNITS) if c.key == "sensor_lag_T_air")
    spec = extended_spec(base.spec, lag, channels, data)
    extended = fit(spec, data, start={**{p.name: p.initial for p in spec.free}, **base.params})
    held = _held_out(spec, extended.params, data)
    added = tuple(p.name for p in spec.free if p.name not in base.params)
    finding = Finding(lag, spec, extended.params, added, base_held, held, block_test(base_held, held), 0.0,
                      parent=(base.spec, base.params))
    causes, leads, final, final_held = _causes([finding], extended, held, base, base_held, data, channels, [])
    assert causes == [] and leads == [finding] and final is base
    assert set(finding.not_identified) == set(added), finding.not_identified
    assert finding.lead_reasons and all("not identified" in r for r in finding.lead_reasons)


@pytest.mark.parametrize("make,expected", [
    (lambda tmp: tmp / "missing.h5", "not found"),
    (lambda tmp: (tmp / "notes.h5").write_text("not a run") and tmp / "notes.h5", "cannot be opened as HDF5"),
])
def test_bad_validate_input_is_one_line_exit_2(tmp_path, capsys, make, expected):
    fitted, _ = _run_file(tmp_path, "fit.h5", [], 347)
    bad = make(tmp_path)
    capsys.readouterr()
    assert main(["diagnose", str(fitted), "--baseline", "nonlinear", "--validate", str(bad), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err and expected in err, err
