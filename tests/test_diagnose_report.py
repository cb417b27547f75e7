"""diagnose's report: held-out regimes, residual evidence, the page and its figures, the CLI.

One 30-minute Table 1 run whose plant hides gearbox churning (a housing heat source growing with the
clutch speed squared) is diagnosed once for the module; the CLI test diagnoses its run file again.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import headless_chromium

from benchlab.cli import main
from benchlab.diagnose.engine import diagnose_runs
from benchlab.diagnose.evidence import bin_labels, residual_evidence, shift_offsets, shift_test, column_spectrum
from benchlab.diagnose.regimes import COOLDOWN_SPLIT_S, regime_errors, regime_labels
from benchlab.diagnose.report import summarise
from benchlab.identify.fit import simulate_outputs
from benchlab.model.params import paper_params
from benchlab.runfile import write_run
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

UNRELATED = ("T_ambient", "load_torque", "time")


def _churn_run(duration_s: float, seed: int = 7):
    plant = P.ThermalPlant(paper_params("nonlinear"), [P.gearbox_churning(40)])
    return run_schedule(table1_schedule(seed, duration_s=duration_s), plant, seed=seed)


@pytest.fixture(scope="module")
def churn():
    run = _churn_run(1800)
    diagnosis = diagnose_runs([run], "nonlinear", seed=0)
    return run, diagnosis, summarise(diagnosis, "nonlinear")


def test_nrmse_is_per_channel_then_averaged(churn):
    """Contract §5: 100 · RMSE / (max − min of the measured signal) for each channel, then the mean."""
    _, diagnosis, summary = churn
    held = diagnosis.baseline_held
    per_channel = []
    for channel, residual in held.residuals()[0].items():
        target = held.datasets[0].targets[channel]
        per_channel.append(100 * np.sqrt(np.nanmean(residual ** 2)) / (np.nanmax(target) - np.nanmin(target)))
    assert summary["baseline"]["nrmse_pct"] == pytest.approx(np.mean(per_channel), rel=1e-12)


def test_regimes_are_computed_on_held_out_residuals(churn):
    _, diagnosis, summary = churn
    held = diagnosis.baseline_held
    assert summary["regimes"]["baseline"] == regime_errors(held)
    residuals, labels = held.residuals()[0], regime_labels(held.datasets[0])
    in_sample = simulate_outputs(diagnosis.baseline.spec.network, diagnosis.baseline.params, held.datasets[0])
    for group, label in (("phase", "open"), ("engine_speed_rpm", ">=1750"), ("cooldown", f"<{COOLDOWN_SPLIT_S:g} s")):
        for channel in ("T_flywheel", "T_air", "T_housing"):
            err = residuals[channel][(labels[group] == label) & np.isfinite(residuals[channel])]
            entry = summary["regimes"]["baseline"][group][label]["channels"][channel]
            assert entry["samples"] == err.size > 0
            assert entry["rmse_K"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
            fitted = (in_sample[channel] - held.datasets[0].targets[channel])[(labels[group] == label)]
            assert entry["rmse_K"] != pytest.approx(np.sqrt(np.nanmean(fitted ** 2)), rel=1e-3)  # not in-sample
    # the final model's regimes are its own held-out errors, and the hidden source's fix shows in the housing
    whole = summary["regimes"]
    assert whole["best"]["all"]["all"]["rmse_K"] == pytest.approx(diagnosis.final_held.rmse, rel=1e-12)
    assert (whole["best"]["all"]["all"]["channels"]["T_housing"]["rmse_K"]
            < 0.5 * whole["baseline"]["all"]["all"]["channels"]["T_housing"]["rmse_K"])


def test_evidence_ranks_the_hidden_signal_above_unrelated_ones(churn):
    _, _, summary = churn
    rows = summary["evidence"]
    top = rows[0]
    assert (top["signal"], top["channel"], top["form"]) == ("clutch_speed", "T_housing", "rate")
    assert top["p_value"] < 0.01 and top["explained_pct"] > 30 > top["shifted_pct"]
    first = {name: next(i for i, r in enumerate(rows) if r["signal"] == name) for name in UNRELATED}
    assert all(rank > 0 for rank in first.values())
    assert {r["signal"] for r in rows} >= {"engine_speed", "slip_speed", "clutch_state", "clutch_torque",
                                            "friction_power", "T_flywheel", "T_air", "T_housing", "time",
                                            "model T_pressure_plate", "model T_housing"}


def test_evidence_on_the_right_model_finds_nothing_strong(churn):
    """The final model holds the churning: what is left of its residuals follows clutch speed no more."""
    _, diagnosis, _ = churn
    rows = residual_evidence(diagnosis.final_held, diagnosis.final.spec, diagnosis.final.params)
    housing = next(r for r in rows if (r.signal, r.channel, r.form) == ("clutch_speed", "T_housing", "rate"))
    assert housing.explained_pct < 10


def test_shift_test_survives_autocorrelation_that_fools_a_sample_count():
    """Slow residuals against unrelated slow signals: binned means explain a lot, yet the shift test stays calm;
    a real dependence on an operating-point signal (levels held for 16 samples) is still found."""
    rng = np.random.default_rng(3)
    n, runs = 2048, 20
    offsets = shift_offsets([n], rng)
    p_unrelated, shares = [], []
    for _ in range(runs):
        residual = np.zeros(n)
        for k in range(1, n):  # AR(1), time constant 300 samples
            residual[k] = residual[k - 1] * (1 - 1 / 300) + rng.normal()
        signal = np.cumsum(rng.normal(size=n))
        labels = bin_labels(signal)
        share, _, p = shift_test([column_spectrum(residual[:, None])], [labels], offsets)
        p_unrelated.append(p[0])
        shares.append(share[0])
    assert np.median(shares) > 0.2  # an F-test with n samples would call nearly all of these significant
    assert np.mean(np.array(p_unrelated) < 0.05) <= 0.15
    signal = np.repeat(rng.normal(size=n // 16), 16)
    related = 10.0 * signal + residual  # about the residual's own spread
    _, _, p = shift_test([column_spectrum(related[:, None])], [bin_labels(signal)], offsets)
    assert p[0] < 0.01


def test_shift_test_share_is_the_correlation_ratio():
    rng = np.random.default_rng(4)
    residual = rng.normal(size=(500, 1))
    residual[::9] = np.nan
    labels = rng.integers(0, 3, 500)
    share, _, _ = shift_test([column_spectrum(residual)], [labels], shift_offsets([500], rng, 9))
    r, lab = residual[np.isfinite(residual[:, 0]), 0], labels[np.isfinite(residual[:, 0])]
    between = sum((lab == b).sum() * (r[lab == b].mean() - r.mean()) ** 2 for b in range(3))
    assert share[0] == pytest.approx(between / np.sum((r - r.mean()) ** 2), rel=1e-9)


def test_cli_report_writes_the_page_and_figures_and_keeps_the_contract(churn, tmp_path, capsys):
    run, _, _ = churn
    path = tmp_path / "churn.h5"
    write_run(path, run, run.attrs["dt"], protocol="table1")
    out = tmp_path / "report"
    assert main(["diagnose", str(path), "--baseline", "nonlinear", "--json", "--report", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"baseline", "findings", "best"} <= set(result)
    assert set(result["baseline"]) >= {"model", "rmse_K", "nrmse_pct"}
    assert set(result["best"]) >= {"model", "rmse_K", "nrmse_pct"}
    for f in result["findings"]:
        assert set(f) >= {"signal", "mechanism", "summary", "extension", "rmse_before_K", "rmse_after_K", "gain_pct"}
    assert result["findings"][0]["signal"] == "clutch_speed"
    assert result["evidence"][0]["signal"] == "clutch_speed"
    page = (out / "diagnose.md").read_text()
    for heading in ("## What is wrong", "## Where", "## Why", "## What was added", "## How much better"):
        assert heading in page
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", page)
    assert {"regimes.png", "worst_window.png", "evidence.png", "gains.png"} <= set(figures)
    assert any(name.startswith("finding_1_") for name in figures)
    html_page = (out / "diagnose.html").read_text()  # the same page for a browser, every figure in it
    assert all(f'<img src="{name}"' in html_page for name in figures) and "<table>" in html_page
    assert "an unnamed bench (the run file has no bench attribute)" in html_page  # written without a `bench`
    for name in figures:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "q_clutch_speed_T" in page and "W (at the signal's maximum)" in page


def test_human_report_names_the_worst_held_out_regime(churn, capsys):
    from benchlab.commands.diagnose import print_report

    _, _, summary = churn
    print_report(summary)
    line = next(line for line in capsys.readouterr().out.splitlines() if "worst regime" in line)
    assert "held-out" in line and "T_housing" in line


@pytest.mark.parametrize("case", ["missing", "short", "report_is_file"])
def test_bad_input_exits_2_with_one_line(case, tmp_path, capsys):
    path = tmp_path / "run.h5"
    args = ["diagnose", str(path)]
    if case == "short":
        run = _churn_run(300)
        write_run(path, run, run.attrs["dt"], protocol="table1")
    elif case == "report_is_file":
        (tmp_path / "taken").write_text("")
        args += ["--report", str(tmp_path / "taken")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("benchlab diagnose:")


@pytest.mark.skipif(headless_chromium.available() is not None, reason=str(headless_chromium.available()))
def test_hostile_run_attributes_run_no_script_in_the_page(churn, tmp_path):
    from benchlab.diagnose.page import write_page

    run, diagnosis, summary = churn
    hostile = run.copy()
    hostile.attrs = {**run.attrs, "source": headless_chromium.HOSTILE, "bench": headless_chromium.HOSTILE,
                     "protocol": headless_chromium.HOSTILE}
    page = write_page(diagnosis, summary, [hostile], tmp_path).with_suffix(".html")
    browser = headless_chromium.Chromium()
    try:
        state = headless_chromium.page_state(browser, page)
    finally:
        browser.close()
    headless_chromium.assert_inert(state, "benchlab diagnose – " + headless_chromium.HOSTILE.rsplit("/", 1)[-1])


def _groups(values_and_errors):
    return [{"parameter": "R0", "group": str(i), "value": v, "standard_error": se}
            for i, (v, se) in enumerate(values_and_errors)]


def test_a_split_is_named_only_where_groups_differ_beyond_their_errors():
    """The issue's case, 43.48 ± 1559 against 43.24 ± 1550 K/W, is one value told twice; 40 ± 0.5 against 43 ± 0.5
    (4.2 combined errors apart) are runs that disagree; a NaN error separates nothing."""
    from benchlab.diagnose.report import split_reasons

    assert split_reasons(_groups([(43.48, 1559.0), (43.24, 1550.0)]))
    assert split_reasons(_groups([(40.0, 0.5), (43.0, 0.5)])) == []
    assert split_reasons(_groups([(40.0, float("nan")), (43.0, 0.5)]))
    assert split_reasons(_groups([(40.0, 0.5), (40.1, 0.5), (43.0, 0.5)])) == []  # one pair apart is enough


class _Finding:
    """What label_json reads of a finding."""

    def __init__(self, not_identified=None, lead_reasons=()):
        self.not_identified = dict(not_identified or {})
        self.lead_reasons = [f"{k} not identified: {v}" for k, v in self.not_identified.items()] + list(lead_reasons)


def test_labels_patch_before_lead_before_cause():
    """A model left beyond the floor, a parameter not identified or an inseparable split makes a patch; a gain that
    does not carry to unseen runs (alone) a lead; nothing of these a cause."""
    from benchlab.diagnose.report import label_json

    within, beyond = {"beyond_library": False, "best_ratio": 1.2}, {"beyond_library": True, "best_ratio": 10.4}
    assert label_json(_Finding(), within, []) == {"label": "cause", "label_reasons": []}
    assert label_json(_Finding(), beyond, [])["label"] == "patch"
    assert label_json(_Finding({"q0": "standard error above value"}), within, [])["label"] == "patch"
    assert label_json(_Finding(), within, _groups([(43.48, 1559.0), (43.24, 1550.0)]))["label"] == "patch"
    lead = label_json(_Finding(lead_reasons=["its gain does not carry"]), within, [])
    assert lead == {"label": "lead", "label_reasons": ["its gain does not carry"]}


def test_no_json_names_a_cause_beside_beyond_library(churn):
    _, _, summary = churn
    for f in summary["findings"] + summary["leads"]:
        assert f["label"] in {"cause", "lead", "patch"} and (f["label"] == "cause") == (not f["label_reasons"])
        assert not (f["label"] == "cause" and summary["floor"]["beyond_library"])
        if f["label"] == "cause":
            assert not f["not_identified"] and not f.get("reasons")


def test_a_source_on_top_of_the_measured_friction_power_creates_energy(churn):
    """The library's friction-power source at the plate, at +50 W at the signal's maximum, adds net heat to what the
    model already injects: energy created; at 0 W it adds none; the churning source (clutch speed) reads no
    measured power and is not judged by this rule."""
    from types import SimpleNamespace

    from benchlab.diagnose.library import channel_source, source_name
    from benchlab.diagnose.report import energy_reasons

    _, diagnosis, _ = churn
    assert all(energy_reasons(f, diagnosis) == [] for f in diagnosis.findings)
    base = diagnosis.baseline.spec.definition
    channels = {k: np.concatenate([d.channels[k] for d in diagnosis.final_held.datasets])
                for k in diagnosis.final_held.datasets[0].channels}
    extended = channel_source(("friction_power",), "P", (None,))(base, channels)
    tag = source_name(("friction_power",), "P", (None,)).removeprefix("source_")

    def finding(q: float, parent: object = None):
        return SimpleNamespace(spec=SimpleNamespace(definition=extended), params={f"q_{tag}": q, f"n_{tag}": 1.0},
                               parent=parent)
    assert energy_reasons(finding(50.0), diagnosis) and "creates energy" in energy_reasons(finding(50.0), diagnosis)[0]
    assert energy_reasons(finding(0.0), diagnosis) == []
    # the source is another finding's where the model this one was measured against already holds it
    assert energy_reasons(finding(50.0, (SimpleNamespace(definition=extended), {})), diagnosis) == []


def _alternatives(diagnosis):
    """Each finding and lead of the diagnosis that has alternatives, with them (the churn run's source on the clutch
    speed is not told apart from the same source gated by the clutch state)."""
    tied = [f for f in [*diagnosis.findings, *diagnosis.leads] if f.alternatives]
    assert tied, "the churn diagnosis no longer has a tie: pick a fixture that does"
    return tied


def test_an_alternative_keeps_its_fit_on_the_diagnosed_runs(churn):
    """The values kept on `engine.Alternative` are its fit, not its nested start: in sample they beat the baseline by
    about the held-out gain that let it pass, as the named extension's kept fit does."""
    from benchlab.diagnose.engine import HeldOut

    _, diagnosis, _ = churn
    datasets = diagnosis.final_held.datasets

    def rmse(spec, params) -> float:
        return HeldOut(datasets, [simulate_outputs(spec.network, {**spec.fixed, **params}, d) for d in datasets],
                       []).rmse

    baseline = rmse(diagnosis.baseline.spec, diagnosis.baseline.params)
    for finding in _alternatives(diagnosis):
        for a in finding.alternatives:
            assert rmse(a.spec, a.params) < (1 - a.gain_pct / 200) * baseline
            assert rmse(*a.named) < (1 - finding.gain_pct / 200) * baseline


def test_each_tie_ranks_the_sensor_places_in_the_json(churn):
    """Every place both models have is ranked: the unmeasured plate removes more of its own estimate variance than
    any measured place; the finding against itself gains nothing anywhere, against the alternative something."""
    from benchlab.design.sensors import rank_diagnosed_sensors

    _, diagnosis, summary = churn
    tied = [f for f in [*summary["findings"], *summary["leads"]] if f["alternatives"]]
    for f in tied:
        for a in f["alternatives"]:
            places = {p["channel"]: p for p in a["sensors"]}
            assert set(places) >= {"T_pressure_plate", "T_flywheel", "T_air", "T_housing"}
            assert not places["T_pressure_plate"]["measured"] and places["T_air"]["measured"]
            plate = places.pop("T_pressure_plate")
            assert all(plate["plate_variance_reduction_pct"] > p["plate_variance_reduction_pct"] > 0
                       for p in places.values())
            assert max(p["test_gain"] for p in a["sensors"]) > 0
    finding = _alternatives(diagnosis)[0]
    itself = rank_diagnosed_sensors(finding.alternatives[0].named, [finding.alternatives[0].named],
                                    diagnosis.final_held.datasets)[0]
    assert [p.test_gain for p in itself] == [0.0] * len(itself)


def test_the_page_and_the_terminal_say_where_a_sensor_would_tell_the_tie_apart(churn, capsys):
    from benchlab.commands.diagnose import print_report
    from benchlab.diagnose.page import _added

    _, _, summary = churn
    page = "\n".join(_added(summary))
    assert "On these runs a sensor at `T_pressure_plate` (node `P`, no sensor now) would remove" in page
    assert "to the test statistic between the two; at `T_" in page
    tied = next(f for f in summary["findings"] if f["alternatives"])  # a lead's tie is said as well
    as_lead = "\n".join(_added({**summary, "findings": [], "leads": [tied]}))
    assert f"The lead `{tied['candidate']}` is not told apart from" in as_lead and "would remove" in as_lead
    print_report(summary)
    printed = capsys.readouterr().out
    assert "not told apart from" in printed
    assert "T_pressure_plate (node P, no sensor now): plate variance -" in printed and "test statistic +" in printed
