"""`benchlab wear` on the command line, the clutch file and its bad-input errors."""

from __future__ import annotations

import contextlib
import io
import json
import re
import tomllib
from pathlib import Path

import pytest

from benchlab.cli import main
from benchlab.errors import InputError
from benchlab.model.params import paper_params, save_params
from benchlab.runfile import write_run
from benchlab.wear.clutchfile import DEFAULT_DOC, default_clutch, load_clutch
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "clutch.toml"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A five-minute Table 1 run and the paper's parameters, as files."""
    root = tmp_path_factory.mktemp("wear")
    run = run_schedule(table1_schedule(5, duration_s=300), ThermalPlant(), seed=5)
    write_run(root / "run.h5", run, run.attrs["dt"], protocol="table1")
    save_params(root / "p.json", paper_params())
    launches = sum(e["event"] == "launch_start" for e in run.attrs["events"])
    return root / "run.h5", root / "p.json", launches, float(run["friction_power"].sum() * run.attrs["dt"])


@pytest.fixture(scope="module")
def json_result(files):
    run, params, _, _ = files
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["wear", str(run), "--params", str(params), "--clutch", str(EXAMPLE), "--json",
                     "--predict", "5000", "--paths", "100", "--seed", "4"])
    return code, json.loads(out.getvalue())


def test_json_has_the_contract_keys_and_more(files, json_result):
    _, _, launches, energy = files
    code, doc = json_result
    assert code == 0
    assert doc["engagements"] == launches == len(doc["engagement_details"])
    assert doc["friction_energy_J"] == pytest.approx(energy, rel=5e-3)
    for side in ("plate", "flywheel"):
        assert doc["wear"][side]["wear_run_mm"] > 0
        assert doc["wear"][side]["energy_J"] == pytest.approx(0.5 * doc["friction_energy_J"])
    assert set(doc["health"]) >= {"transmissible_torque_Nm", "max_engine_torque_Nm", "health", "worn"}
    life = doc["life"]
    assert life["horizon_engagements"] == 5000 and life["paths"] == 100 and life["seed"] == 4
    assert life["engagements"]["p10"] <= life["engagements"]["p50"] <= life["engagements"]["p90"]
    assert 0.0 <= life["p_fail_within_horizon"] <= 1.0
    assert doc["mu_estimate"] is None  # the simulated bench records no actuator position


def test_example_clutch_file_is_the_default(json_result, files, capsys):
    assert tomllib.loads(EXAMPLE.read_text()) == DEFAULT_DOC
    assert load_clutch(EXAMPLE).maps["spring"].as_lists() == default_clutch().maps["spring"].as_lists()
    run, params, _, _ = files
    assert main(["wear", str(run), "--params", str(params), "--json", "--predict", "5000", "--paths", "100",
                 "--seed", "4"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["wear"] == json_result[1]["wear"] and doc["life"] == json_result[1]["life"]


def test_text_summary_and_plot(files, tmp_path, capsys, monkeypatch):
    import benchlab.wear.plot as wear_plot

    saved = []
    real_save = wear_plot.save
    monkeypatch.setattr(wear_plot, "save", lambda fig, path: (saved.append(fig), real_save(fig, path))[1])
    run, params, launches, _ = files
    png = tmp_path / "wear.png"
    assert main(["wear", str(run), "--params", str(params), "--plot", str(png), "--paths", "50"]) == 0
    power, temperature = saved[0].axes[:2]  # each curve named in a legend, subscripts as mathtext (issue 46)
    assert [t.get_text() for t in power.get_legend().get_texts()] == ["friction power", "cumulative energy"]
    assert all(t.get_text().startswith(r"$\vartheta_") for t in temperature.get_legend().get_texts())
    out = capsys.readouterr().out
    assert f"in {launches} engagements" in out and "P10/P50/P90" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def _edit(text: str, pattern: str, replacement: str) -> str:
    new = re.sub(pattern, replacement, text, count=1, flags=re.S)
    assert new != text
    return new


BAD_CLUTCH = {
    "missing map": (lambda t: _edit(t, r"\[maps\.spring\][^\n]*\n.*?\n\n", ""), "maps.spring"),
    "non-monotonic axis": (lambda t: _edit(t, r"\[20\.0, 100\.0, 150\.0", "[20.0, 150.0, 100.0"),
                           "maps.friction.temperature_C"),
    "negative radius": (lambda t: _edit(t, r"mean_radius_m = 0\.1", "mean_radius_m = -0.1"), "clutch.mean_radius_m"),
    "unreadable TOML": (lambda t: t + "\n[maps.friction\nmu = \n", "file"),
    "missing value list": (lambda t: _edit(t, r"mu = \[0\.30[^\n]*\n", ""), "maps.friction.mu"),
    "length mismatch": (lambda t: _edit(t, r"factor = \[1\.0, 0\.98, 0\.95, 0\.92\]", "factor = [1.0, 0.98]"),
                        "maps.friction_slip.factor"),
    "odd face count": (lambda t: _edit(t, r"friction_faces = 2", "friction_faces = 3"), "clutch.friction_faces"),
    "text for a number": (lambda t: _edit(t, r"max_engine_torque_Nm = 180\.0", 'max_engine_torque_Nm = "high"'),
                          "clutch.max_engine_torque_Nm"),
    "negative wear rate": (lambda t: _edit(t, r"mm3_per_J = \[3\.0e-5", "mm3_per_J = [-3.0e-5"),
                           "maps.wear_rate.mm3_per_J"),
    "limit above height": (lambda t: _edit(t, r"min_height_mm = 2\.5", "min_height_mm = 4.0"), "lining.min_height_mm"),
    "misspelt state key": (lambda t: _edit(t, r"wear_plate_mm = 0\.0", "wear_plat_mm = 0.4"), "state.wear_plat_mm"),
    "misspelt map key": (lambda t: _edit(t, r"mm3_per_J = ", "mm3_per_j = "), "maps.wear_rate.mm3_per_j"),
    "unknown map": (lambda t: t + "\n[maps.frictoin]\ntemperature_C = [20.0]\nmu = [0.3]\n", "maps.frictoin"),
    "unknown section": (lambda t: t + "\n[lineing]\nheight_mm = 3.0\n", "lineing"),
}


@pytest.mark.parametrize("case", sorted(BAD_CLUTCH))
def test_bad_clutch_file_is_one_line_exit_2(case, files, tmp_path, capsys):
    edit, field = BAD_CLUTCH[case]
    bad = tmp_path / "clutch.toml"
    bad.write_text(edit(EXAMPLE.read_text()))
    with pytest.raises(InputError) as info:
        load_clutch(bad)
    assert info.value.field == field
    run, params, _, _ = files
    assert main(["wear", str(run), "--params", str(params), "--clutch", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err and field in err and "Traceback" not in err


def test_missing_clutch_file_and_bad_horizon(files, tmp_path, capsys):
    run, params, _, _ = files
    assert main(["wear", str(run), "--params", str(params), "--clutch", str(tmp_path / "none.toml")]) == 2
    assert "none.toml: file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:  # refused by argparse, before anything is read
        main(["wear", str(run), "--params", str(params), "--predict", "0"])
    assert exit_.value.code == 2 and "--predict" in capsys.readouterr().err
