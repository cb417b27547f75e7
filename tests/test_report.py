"""benchlab report: figures and page written, the page's error figures are benchlab.identify.metrics', Fig. 5 tells the
linear model from the nonlinear one on a validation run, Fig. 3 shows the sweep's cool-downs, bad input exits 2."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

import benchlab
import headless_chromium
from benchlab.cli import main
from benchlab.model.clutch import PREDICTED_CHANNELS
from benchlab.identify.cooldown import CooldownResult, store
from benchlab.identify.metrics import channel_nrmse_pct, channel_rmse_k, nrmse_pct, rmse_k
from benchlab.model.params import paper_params, save_params
from benchlab.report import build, write_report
from benchlab.report.html import markdown_html
from benchlab.report.resistance import resistance
from benchlab.runfile import write_run
from benchlab.runner.session import RunRequest, execute
from sim_bench.bench import SimulatedBench
from sim_bench.plant import ThermalPlant

FIGURES = ("fig4_fit.png", "fig5_validation_1.png", "fig3_resistance.png", "residuals.png")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def bench(tmp_path_factory, short_run):
    """A Table 1 run, a validation run, a two-point cooldown sweep and the paper's two parameter files; the runs on
    the paper's plant, whose parameters the files hold (the figures are checked against them)."""
    d = tmp_path_factory.mktemp("report")
    write_run(d / "run.h5", short_run, short_run.attrs["dt"], protocol="table1")
    for protocol, name, options in (("validation", "validation.h5", {"seed": 3, "cycles": 0}),
                                    ("cooldown-sweep", "sweep.h5", {"seed": 2, "grid": "800:1,2000:0"})):
        code, _ = execute(RunRequest(protocol, d / name, install_signals=False, bench=SimulatedBench(ThermalPlant()),
                                     **options))
        assert code == 0
    save_params(d / "linear.json", paper_params("linear"), {"uncertainty": {"R0": 0.004}})
    save_params(d / "nonlinear.json", paper_params("nonlinear"))
    return d


@pytest.fixture(scope="module")
def report(bench):
    out = bench / "out"
    code = main(["report", str(bench / "run.h5"), "--params", str(bench / "linear.json"),
                 "--compare", str(bench / "nonlinear.json"), "--out", str(out),
                 "--validate", str(bench / "validation.h5"), "--sweep", str(bench / "sweep.h5")])
    assert code == 0
    return out


def test_the_page_is_also_html_with_every_figure(report):
    markdown, page = (report / "report.md").read_text(), (report / "report.html").read_text()
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", markdown)
    assert len(figures) >= 4 and all(f'<img src="{name}"' in page for name in figures)
    tables = len(re.findall(r"^\|(---\|)+$", markdown, flags=re.M))
    assert tables >= 3 and page.count("<table>") == tables
    assert "|---|" not in page and "![" not in page and "K/W" in page  # rendered, units kept


def page_scores(page) -> dict[tuple[str, str, str], tuple[float, float]]:
    """(run, model, channel or "all") -> (RMSE K, NRMSE %) from the page's error-figure table."""
    rows = {}
    for line in page.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and ("`T_" in cells[2] or "**all**" in cells[2]):
            channel = re.search(r"`(\w+)`", cells[2])
            rows[(cells[0].strip("`"), cells[1], channel.group(1) if channel else "all")] = (float(cells[3]),
                                                                                           float(cells[4]))
    return rows


def test_command_writes_the_figures_and_the_page(report):
    page = (report / "report.md").read_text()
    for name in FIGURES:
        data = (report / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 20_000, name
        assert f"]({name})" in page
    assert "| `a1` | K/W | 0 | — | 0.35 | — |" in page  # the parameters of both files, with units
    assert "| `R0` | K/W | 0.15 | 0.004 | 0.15 | — |" in page  # and the standard error the file holds


@pytest.mark.parametrize("name", ["run.h5", "validation.h5"])
def test_page_error_figures_are_benchlab_metrics(bench, report, name):
    scores = page_scores(report / "report.md")
    run = benchlab.load_run(bench / name)
    for model in ("linear", "nonlinear"):
        sim = benchlab.simulate(run, benchlab.load_params(bench / f"{model}.json"))
        expected = {"all": (rmse_k(run, sim), nrmse_pct(run, sim))}
        expected |= {c: (channel_rmse_k(run, sim)[c], channel_nrmse_pct(run, sim)[c]) for c in PREDICTED_CHANNELS}
        for channel, (rmse, nrmse) in expected.items():
            page_rmse, page_nrmse = scores[(name, model, channel)]
            assert page_rmse == pytest.approx(rmse, abs=5.1e-5), (model, channel)
            assert page_nrmse == pytest.approx(nrmse, abs=5.1e-4), (model, channel)


def test_fig5_linear_model_misses_the_varying_cooldowns(report):
    scores = page_scores(report / "report.md")
    linear, nonlinear = scores[("validation.h5", "linear", "all")], scores[("validation.h5", "nonlinear", "all")]
    assert linear[0] > 3 * nonlinear[0] and linear[0] > 0.5  # RMSE, K
    assert linear[1] > 3 * nonlinear[1]  # NRMSE, %


def test_fig3_table_has_the_sweeps_cooldowns_near_the_true_law(report):
    page = (report / "report.md").read_text()
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in page.splitlines()
            if re.match(r"\| \d+ \| \d+ \| [01] \|", line)]
    assert [(float(r[1]), int(r[2])) for r in rows] == [(800.0, 1), (2000.0, 0)]
    assert "fitted here" in page and "has no `/analysis`" in page  # the sweep was not analysed: fitted, and said so
    truth = paper_params("nonlinear")
    for r in rows:
        true_r = float(resistance(truth, np.array([float(r[1])]), int(r[2]))[0][0])
        assert float(r[3]) == pytest.approx(true_r, rel=0.02)
        assert float(r[6]) == pytest.approx(true_r, abs=1e-4)  # the nonlinear file's eq. (11) at that point


def test_python_api_without_validation_shows_fig5_on_the_run(tmp_path, short_run):
    page = write_report(short_run, paper_params("nonlinear"), tmp_path / "out")
    assert page == tmp_path / "out" / "report.md"
    assert {p.name for p in page.parent.glob("*.png")} == set(FIGURES)
    scores = page_scores(page)
    assert {(run, model) for run, model, _ in scores} == {(short_run.attrs["source"], "nonlinear")}


def _bad_params(bench):
    path = bench / "bad.json"
    path.write_text(json.dumps({"model": "nonlinear", "params": {"C_P": 1800.0}}))
    return ["--params", str(path)], "bad.json: params.C_F"


@pytest.mark.parametrize("case", ["missing run", "params field", "validation not hdf5", "sweep without events",
                                  "out is a file"])
def test_bad_input_is_one_line_and_exit_2(bench, tmp_path, capsys, case):
    run, params = str(bench / "run.h5"), ["--params", str(bench / "nonlinear.json")]
    extra: list[str] = []
    out = tmp_path / "out"
    if case == "missing run":
        run, expected = str(tmp_path / "nothing.h5"), "nothing.h5: file: an existing run file"
    elif case == "params field":
        params, expected = _bad_params(bench)
    elif case == "validation not hdf5":
        text = tmp_path / "v.h5"
        text.write_text("time,T_air\n0,20\n")
        extra, expected = ["--validate", str(text)], "v.h5: file: an HDF5 run file"
    elif case == "sweep without events":
        extra, expected = ["--sweep", run], "run.h5: protocol: a cool-down sweep run"
    else:
        out.write_text("")
        expected = "out: --out: a directory"
    code = main(["report", run, *params, "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("benchlab report: ") and expected in err, err
    assert "Traceback" not in err


def test_resistance_band_uses_the_parameter_correlations():
    """The delta-method SE of eq. (11) matches Monte Carlo draws of correlated parameters (and not the uncorrelated sum)."""
    from benchlab.report.resistance import resistance
    names = ["a1", "b1", "R0"]
    se = np.array([0.01, 2e-5, 0.004])
    corr = np.array([[1.0, 0.3, -0.9], [0.3, 1.0, -0.2], [-0.9, -0.2, 1.0]])
    params = paper_params("nonlinear")
    params.extra = {"uncertainty": dict(zip(names, se)), "correlation": {"names": names, "matrix": corr.tolist()}}
    speed = np.array([700.0, 1500.0, 3000.0])
    _, sigma = resistance(params, speed, state=1)
    draws = np.random.default_rng(0).multivariate_normal([params[n] for n in names], corr * np.outer(se, se), 20000)
    r = draws[:, 0:1] * np.exp(draws[:, 1:2] * speed) + draws[:, 2:3]
    assert sigma == pytest.approx(r.std(axis=0), rel=0.05)
    params.extra.pop("correlation")  # without it, a1 and R0 (correlation -0.9) add up where both matter
    assert resistance(params, speed, state=1)[1][0] > 1.5 * r.std(axis=0)[0]


def test_fig5_title_names_the_temperatures_it_plots(monkeypatch, short_run, tmp_path):
    from benchlab.report import timeseries
    from benchlab.report.plotting import SYMBOLS
    from benchlab.report.scores import estimate

    figures = []
    monkeypatch.setattr(timeseries, "save", lambda fig, path: figures.append(fig))
    timeseries.plot_comparison(short_run, [estimate(short_run, paper_params("nonlinear"), "nonlinear")],
                               tmp_path / "fig5.png")
    fig = figures[0]
    plotted = [ax.get_ylabel().removesuffix(" (°C)") for ax in fig.axes if ax.get_ylabel().endswith("(°C)")]
    title = fig._suptitle.get_text()
    assert plotted == [SYMBOLS["T_flywheel"], SYMBOLS["T_air"]]
    assert [s for s in SYMBOLS.values() if s in title] == plotted


def test_identify_and_report_test_the_same_residuals(short_run):
    """One start (the run's measured temperatures), one test, one sign: identify's verdicts are the report's."""
    from benchlab.identify.api import identify
    from benchlab.report.residuals import residuals
    from benchlab.report.scores import estimate

    result = identify([short_run], "linear", starts=1)
    page = residuals(short_run, estimate(short_run, result.params, "linear"), result.params)
    assert result.residuals[short_run.attrs["source"]] == page.tests
    # the linear model misses the convection law: the air, which the convection heats, is not white; the housing,
    # two links away, may carry less structure than the effect threshold (identify.residuals)
    assert not page.tests["T_air"]["white"] and page.tests["T_air"]["structure_K"] > 0.05


def test_residual_tests_pass_the_true_structure(short_run):
    """The nonlinear model on the nonlinear plant: every channel white, no input correlation beyond the threshold
    (benchmarks/coverage_study.py measures the share of seeds; this is one)."""
    from benchlab.identify.api import identify

    tests = identify([short_run], "nonlinear", starts=1).residuals[short_run.attrs["source"]]
    assert all(t["white"] and not t["input_correlated"] for t in tests.values()), tests
    assert all(t["structure_K"] < t["effect_threshold_K"] / 3 for t in tests.values())


def test_residuals_are_simulated_minus_measured(short_run):
    from benchlab.identify.residuals import run_residuals
    from benchlab.identify.metrics import RESIDUAL_LABEL

    warm = dict(paper_params("nonlinear"), C_F=0.7 * paper_params("nonlinear")["C_F"])  # flywheel heats faster
    cool = dict(paper_params("nonlinear"), C_F=1.4 * paper_params("nonlinear")["C_F"])
    assert RESIDUAL_LABEL == "simulated − measured"
    for params, sign in ((warm, 1.0), (cool, -1.0)):
        res = run_residuals(short_run, benchlab.simulate(short_run, params))
        assert sign * np.nanmean(res.residual["T_flywheel"]) > 0.1


def test_page_states_the_residual_sign_and_start(report):
    text = (report / "report.md").read_text()
    assert "Residual = simulated − measured" in text and "measured temperatures" in text


def test_a_sweeps_stored_analysis_is_read_not_fitted_again(bench, tmp_path, monkeypatch):
    """`benchlab cooldown` stored /analysis: the report shows that table and says so; no cool-down is fitted."""
    sweep = tmp_path / "sweep.h5"
    shutil.copy(bench / "sweep.h5", sweep)
    rows = [CooldownResult(0, 800.0, 1, 0.0, 100.0, 700.0, 0.1234, 0.001, 0.0025, 75.0, 0.5, 0.04, 600, 1.1, 0.12),
            CooldownResult(1, 2000.0, 0, 2000.0, 1500.0, 2100.0, 0.2345, 0.002, 0.004, 74.0, 0.6, 0.05, 600, 0.9)]
    store(sweep, rows, None, "identified.json")
    monkeypatch.setattr(build, "analyse", lambda *a, **k: pytest.fail("fitted although /analysis is stored"))
    results, source = build.sweep_cooldowns(sweep, paper_params("nonlinear"))
    assert results[0] == rows[0] and results[1].R == 0.2345 and np.isnan(results[1].R_true)
    assert "`/analysis`" in source and "identified.json" in source


def test_renderer_turns_no_strangers_html_into_markup():
    page = markdown_html("# t\n\n<details><script>alert(1)</script>\n\n[a](javascript:alert(1)) "
                         "[b](JaVa&#x53;cript:1) [c](http://x/y?a=1&b=2) [d](fig.png)\n\n![e](data:text/html,x)\n\n"
                         "<details><summary>ok</summary>\n\n</details>", "t")
    assert "<script" not in page and "<img" not in page
    assert re.findall(r'href="([^"]*)"', page) == ["http://x/y?a=1&amp;b=2", "fig.png"]
    assert "&lt;details&gt;&lt;script&gt;" in page and "<details><summary>ok</summary>" in page


@pytest.mark.skipif(headless_chromium.available() is not None, reason=str(headless_chromium.available()))
def test_hostile_run_attributes_run_no_script_in_the_page(tmp_path, short_run):
    run = short_run.copy()
    run.attrs = {**short_run.attrs, "source": headless_chromium.HOSTILE, "bench": headless_chromium.HOSTILE,
                 "protocol": headless_chromium.HOSTILE}
    page = write_report(run, paper_params("linear"), tmp_path).with_suffix(".html")
    browser = headless_chromium.Chromium()
    try:
        state = headless_chromium.page_state(browser, page)
    finally:
        browser.close()
    headless_chromium.assert_inert(state, "benchlab report – " + run.attrs["source"].rsplit("/", 1)[-1])


@pytest.mark.skipif(headless_chromium.available() is not None, reason=str(headless_chromium.available()))
def test_hostile_run_attributes_and_findings_run_no_script_in_the_jobs_index(tmp_path, short_run):
    from benchlab.report.index import write_index

    hostile = headless_chromium.HOSTILE
    path = tmp_path / "run.h5"
    write_run(path, short_run.iloc[:2000], short_run.attrs["dt"], protocol=hostile,
              attrs={"bench": hostile, "can_log": hostile})
    finding = {"candidate": hostile, "signal": hostile, "mechanism": hostile, "gain_pct": 5.0, "p_value": 0.01,
               "alternatives": [{"candidate": hostile, "gain_pct": 4.0, "tell_apart_by": hostile}]}
    scores = {"rmse_K": 0.1, "nrmse_pct": 1.0}
    page = write_index(tmp_path, {hostile: (path, short_run.iloc[:2000])},
                       {"nonlinear": {"fit": scores, "validation": scores}}, [], paper_params("nonlinear"), {},
                       {"findings": [finding], "baseline": {"model": hostile, "rmse_K": 0.2},
                        "best": {"model": hostile, "rmse_K": 0.1}},
                       {"life": {"engagements": {}, "horizon_engagements": 1000, "p_fail_within_horizon": 0.0},
                        "health": {"health": 1.0, "worn": False}, "engagements": 10, "friction_energy_J": 1e6,
                        "wear": {}},
                       {"verdict": hostile, "peaks": {hostile: {}}, "extrapolation": {}})
    browser = headless_chromium.Chromium()
    try:
        state = headless_chromium.page_state(browser, page)
    finally:
        browser.close()
    headless_chromium.assert_inert(state, "benchlab: the whole job")


def test_a_finding_without_a_signal_shows_no_none():
    """A change of the structure (bridge_F_A) has no signal: the pages show its mechanism alone and a dash, never
    "None" (issue 46)."""
    from benchlab.report.index import _signal_mechanism
    from benchlab.report.markdown import literal

    structural = {"candidate": "bridge_F_A", "signal": None, "mechanism": "capacity"}
    assert _signal_mechanism(structural) == "capacity" and literal(None) == "—"
    assert _signal_mechanism({**structural, "signal": "engine_speed"}) == "engine_speed / capacity"


def test_the_raw_can_log_cell_links_the_log_beside_the_run(tmp_path):
    from benchlab.report.index import _can_log_cell

    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "r.blf").write_bytes(b"")
    run, out = tmp_path / "runs" / "r.h5", tmp_path / "pages"
    assert _can_log_cell(run, "r.blf", out) == '<a href="../runs/r.blf">r.blf</a>'
    assert _can_log_cell(run, "gone.blf", out) == "gone.blf" and _can_log_cell(run, None, out) == "—"
