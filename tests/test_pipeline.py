"""The README's main command, `benchlab pipeline`, end to end on a short simulated bench session."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

from benchlab.cli import main
from benchlab.model.params import load_params
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
    _check_index(tmp_path)


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.targets: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.targets += [v for k, v in attrs if k in ("href", "src")]

    def handle_data(self, data):
        self.text.append(data)


def _check_index(out):
    """One page tells the whole job: every link resolves, the sections are there, the numbers agree."""
    page = _Links()
    page.feed((out / "index.html").read_text())
    assert page.targets and all((out / t).exists() for t in page.targets), page.targets
    for figure in ("report/fig4_fit.png", "report/fig3_resistance.png", "wear.png", "diagnose.json"):
        assert figure in page.targets
    text = " ".join(page.text)
    assert "simulated bench" in text and "reference dry clutch" in text and "2.5 %" in text  # the paper beside ours
    assert -1 < text.find("The nonlinear model ") < text.index("Everything on this page")  # the verdict on top
    for section in ("Misfit at the heating peaks", "Extrapolation", "against the plant's truth", "Cannot be told apart"
                    if "Cannot be told apart" in text else "No alternative", "wear this run"):
        assert section in text, section
    # per long cool-down of the validation run (Fig. 5): both models scored
    rows = re.findall(r"(\d) \| ([^|]+\(\d+–\d+ rpm\)) \| ([\d.]+) % \| ([\d.]+) %", " | ".join(page.text))
    assert len(rows) == 3, rows
    # the paper's plate: hotter than the flywheel while slipping, more so in the plant than the model assumes
    hotter = re.search(r"the plate is ([\d.]+) K hotter than the flywheel in truth, (-?[\d.]+) K by the model", text)
    assert hotter and float(hotter.group(1)) > float(hotter.group(2)), hotter
