"""The README's main command, `benchlab pipeline`, end to end on a short simulated bench session."""

from __future__ import annotations

import json

from benchlab.cli import main
from benchlab.params import load_params
from benchlab.runfile import load_run


def test_pipeline_runs_end_to_end_and_writes_every_product(tmp_path, capsys):
    assert main(["pipeline", "--out", str(tmp_path), "--duration", "1500"]) == 0
    printed = capsys.readouterr().out
    for step in ("run", "validation", "identify", "report", "diagnose", "wear"):
        assert any(line.startswith(step) for line in printed.splitlines()), step
    fitting = load_run(tmp_path / "table1.h5")
    assert fitting.attrs["status"] == "complete" and fitting["time"].iloc[-1] >= 1200
    assert load_params(tmp_path / "nonlinear.json").model == "nonlinear"
    assert load_params(tmp_path / "linear.json").model == "linear"
    diagnosis = json.loads((tmp_path / "diagnose.json").read_text())
    assert {"baseline", "findings", "best"} <= diagnosis.keys()
    assert diagnosis["best"]["rmse_K"] <= diagnosis["baseline"]["rmse_K"]
    for page in ("report/report.md", "diagnose/diagnose.md"):
        assert (tmp_path / page).stat().st_size > 0
    assert json.loads((tmp_path / "wear.json").read_text())["engagements"] > 0
