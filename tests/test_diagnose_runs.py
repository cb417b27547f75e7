"""Runs that disagree: one clutch on two benches (one with a fan on the housing), diagnosed together.

The plant is the simulated bench's own (sim_bench.plant, written without diagnose in view) with the housing's
resistance to ambient set per bench; nothing in diagnose knows which parameter differs, or that any does. The
finding must be "the runs disagree on R_Tamb", with each group's value near the bench it came from, and a correct
model on two runs of one bench must get no such finding.
"""

from __future__ import annotations

import json

import pytest

from benchlab.cli import main
from benchlab.diagnose import diagnose
from benchlab.model.params import paper_params
from benchlab.runfile import write_run
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

RUN_S = 2400.0
PLAIN_K_PER_W, FAN_K_PER_W = 0.08, 0.035  # the two benches: housing to ambient without and with the fan


def _run(seed: int, r_tamb: float | None = None):
    """A RUN_S Table 1 run of the nonlinear clutch on a bench whose housing-to-ambient resistance is `r_tamb`."""
    params = paper_params("nonlinear")
    if r_tamb is not None:
        params["R_Tamb"] = r_tamb
    return run_schedule(table1_schedule(seed, duration_s=RUN_S), ThermalPlant(params, []), seed=seed)


def test_two_benches_that_differ_in_housing_resistance_are_named_as_disagreeing_runs():
    runs = [_run(301, PLAIN_K_PER_W), _run(302, FAN_K_PER_W)]
    result = diagnose(runs, baseline="nonlinear")
    first = result["findings"][0]
    assert (first["mechanism"], first["candidate"]) == ("per_run", "per_run_R_Tamb"), first["candidate"]
    assert first["run_gain_pct"] is None  # another run's value cannot be predicted: exempt, and said so
    values = {g["group"]: g for g in first["per_group"]}
    assert values["0"]["value"] == pytest.approx(PLAIN_K_PER_W, rel=0.05)
    assert values["1"]["value"] == pytest.approx(FAN_K_PER_W, rel=0.05)
    assert all(g["standard_error"] > 0 and g["unit"] == "K/W" for g in values.values())
    assert first["label"] == "cause", first["label_reasons"]  # 0.08 against 0.035 K/W: beyond 2 combined errors
    assert result["floor"]["best_ratio"] < 2.0


def test_a_correct_model_on_two_runs_of_one_bench_gets_no_finding():
    runs = [_run(305), _run(306)]
    result = diagnose(runs, baseline="nonlinear")
    assert result["findings"] == [], [f["candidate"] for f in result["findings"]]


def test_group_by_a_run_attribute_through_the_command_line(tmp_path, capsys):
    """Three runs, two on the plain bench and one with the fan, grouped by their `bench` attribute: one value per
    bench, the plain bench's from both of its runs."""
    paths = []
    for seed, bench, r in ((307, "plain", PLAIN_K_PER_W), (308, "fan", FAN_K_PER_W), (309, "plain", PLAIN_K_PER_W)):
        run = _run(seed, r)
        paths.append(tmp_path / f"{seed}.h5")
        write_run(paths[-1], run, run.attrs["dt"], protocol="table1", attrs={"bench": bench})
    capsys.readouterr()
    assert main(["diagnose", *map(str, paths), "--baseline", "nonlinear", "--group-by", "bench", "--json", "-q"]) == 0
    first = json.loads(capsys.readouterr().out)["findings"][0]
    assert first["candidate"] == "per_run_R_Tamb"
    values = {g["group"]: g for g in first["per_group"]}
    assert values["plain"]["runs"] == [0, 2] and values["fan"]["runs"] == [1]
    assert values["plain"]["value"] == pytest.approx(PLAIN_K_PER_W, rel=0.05)
    assert values["fan"]["value"] == pytest.approx(FAN_K_PER_W, rel=0.05)


def test_group_by_an_attribute_a_run_lacks_is_bad_input(tmp_path, capsys):
    run = _run(310)
    path = tmp_path / "run.h5"
    write_run(path, run, run.attrs["dt"], protocol="table1")
    capsys.readouterr()
    assert main(["diagnose", str(path), str(path), "--baseline", "nonlinear", "--group-by", "bench", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bench" in err[0] and str(path) in err[0]
