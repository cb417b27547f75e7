"""The main job's one page (`index.html`): run → identification → diagnosis → wear, with the figures.

It reads what the job wrote (run files, parameter files, the diagnosis summary, the wear report) and
tells the story in order, the paper's published figures beside benchlab's own, and says plainly which
parts come from the simulated bench and how far the identified model is from the simulated plant's truth.
"""

from __future__ import annotations

import html
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from benchlab.identify.identifiability import recorded
from benchlab.identify.metrics import nrmse_pct, rmse_k
from benchlab.outputs import write_text
from benchlab.model.params import ModelParams
from benchlab.provenance import SIMULATED, bench_text
from benchlab.report.html import STYLE
from benchlab.report.page import error_cell, number
from benchlab.report.scores import estimate
from benchlab.runfile import event_steps, load_attrs, load_events, load_schedule

if TYPE_CHECKING:
    from benchlab.report.showcase import PlateBand

PAGE = "index.html"
#: The paper's published error figures (section 4): Table 1 identification, five validation runs, and the
#: Fig. 5 cool-downs with the engine speed changing (linear against nonlinear model).
PAPER = {"fit": "2.5 %", "validation": "< 10 %", "cooldown_linear": "8.4 %", "cooldown_nonlinear": "3.8 %"}
COOLDOWN_LABEL = "validation_cooldown"


@dataclass(frozen=True)
class Cooldown:
    """One long cool-down of the validation protocol (Fig. 5): its span and each model's error over it."""

    cycle: int
    t_start: float
    t_end: float
    description: str
    nrmse_pct: dict[str, float]
    rmse_k: dict[str, float]
    flywheel_nrmse_pct: dict[str, float]  # the flywheel alone, the temperature the paper's Fig. 5 shows


def validation_cooldowns(path: "str | os.PathLike[str]") -> list[tuple[int, float, float, str]]:
    """(cycle, start s, end s, set-points) of each long cool-down of a validation run: the spans of its steps
    labelled COOLDOWN_LABEL in the stored schedule (the step_start events' steps), described by their phases."""
    events, steps = load_events(path), load_schedule(path)
    spans: dict[int, list[Any]] = {}
    for event, row in zip(events, event_steps(events, steps)):
        if event.kind not in ("step_start", "cycle_start", "run_complete", "run_aborted"):
            continue
        step = steps[row] if event.kind == "step_start" and 0 <= row < len(steps) else None
        inside = step is not None and step.label == COOLDOWN_LABEL
        for c, span in spans.items():  # any other step, or a new cycle, ends an open cool-down
            if span[2] is None and (c != event.cycle or not inside):
                span[2] = event.time
        if inside:
            span = spans.setdefault(event.cycle, [event.time, [], None])
            span[1].append(step.phase)
            span[2] = None
    return [(c, s[0], s[2], " → ".join(s[1])) for c, s in sorted(spans.items()) if s[2] is not None]


def cooldown_scores(run: pd.DataFrame, path: "str | os.PathLike[str]",
                    models: Sequence[tuple[str, ModelParams]]) -> list[Cooldown]:
    """Each model's error over each long cool-down (Fig. 5), from its simulation of the whole validation run.

    The whole run, not each cool-down from its own start: the unmeasured pressure plate is known at the run's
    start (everything at ambient), not at the end of a heat-up.
    """
    time = run["time"].to_numpy()
    sims = {label: estimate(run, params, label).simulated for label, params in models}
    out = []
    for cycle, t0, t1, text in validation_cooldowns(path):
        inside = (time >= t0) & (time <= t1)
        piece = run[inside]
        rpm = piece["engine_speed"].to_numpy()
        text = f"{text} ({rpm.min():.0f}–{rpm.max():.0f} rpm)"
        parts = {label: sim[inside] for label, sim in sims.items()}
        out.append(Cooldown(cycle, t0, t1, text, {k: nrmse_pct(piece, s) for k, s in parts.items()},
                            {k: rmse_k(piece, s) for k, s in parts.items()},
                            {k: nrmse_pct(piece, s, ("T_flywheel",)) for k, s in parts.items()}))
    return out


def mean_cooldown_nrmse(cooldowns: Sequence[Cooldown], model: str, flywheel: bool = False) -> float:
    """A model's NRMSE averaged over the long cool-downs, of the measured channels or of the flywheel alone (the
    figures beside the paper's 3.8 % / 8.4 %); NaN without cool-downs."""
    values = [(c.flywheel_nrmse_pct if flywheel else c.nrmse_pct)[model] for c in cooldowns]
    return sum(values) / len(values) if values else math.nan


def _num(value: Any, digits: int, suffix: str = "") -> str:
    """The report's table cell (`number`), with a unit where there is a number."""
    text = number(value, digits)
    return text if text == "—" else text + suffix


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _figure(out: Path, path: Path, caption: str) -> str:
    if not path.exists():
        return ""
    rel = html.escape(os.path.relpath(path, out))
    return f'<figure><a href="{rel}"><img src="{rel}" alt="{html.escape(caption)}"></a>' \
           f"<figcaption>{html.escape(caption)}</figcaption></figure>"


def _run_section(runs: Mapping[str, tuple[Path, pd.DataFrame]], out: Path) -> str:
    rows = []
    for label, (path, run) in runs.items():
        duration = float(run["time"].iloc[-1] - run["time"].iloc[0])
        attrs = load_attrs(path)
        link = f'<a href="{html.escape(os.path.relpath(path, out))}">{html.escape(path.name)}</a>'
        rows.append([html.escape(label), link,
                     html.escape(attrs.get("protocol", "")), html.escape(bench_text(attrs.get("bench"), short=True, simulated=attrs.get("bench_simulated", ""))),
                     _num(duration / 3600, 2, " h"), str(len(run)),
                     _num(float(run["T_flywheel"].max()), 1, " °C"),
                     _num(float(run["friction_power"].sum()) * float(run.attrs["dt"]) / 1e6, 2, " MJ"),
                     _can_log_cell(path, attrs.get("can_log"), out)])
    return _table(("run", "file", "protocol", "bench", "duration", "samples", "flywheel max", "friction energy",
                   "raw CAN log"), rows)


def _can_log_cell(run_path: Path, can_log: str | None, out: Path) -> str:
    """The run's raw CAN log (a file name beside its run file) as a link where the file is there, else its name."""
    if not can_log:
        return "—"
    log = run_path.parent / can_log
    if not log.is_file():
        return html.escape(can_log)
    return f'<a href="{html.escape(os.path.relpath(log, out))}">{html.escape(can_log)}</a>'


def _identify_section(figures: Mapping[str, Mapping[str, Mapping[str, float]]],
                      cooldowns: Sequence[Cooldown]) -> str:
    rows = []
    for model, fig in figures.items():
        rows.append([model, _num(fig["fit"]["rmse_K"], 3, " K"), _num(fig["fit"]["nrmse_pct"], 2, " %"),
                     _num(fig["validation"]["rmse_K"], 3, " K"), _num(fig["validation"]["nrmse_pct"], 2, " %"),
                     _num(mean_cooldown_nrmse(cooldowns, model), 2, " %"),
                     _num(mean_cooldown_nrmse(cooldowns, model, flywheel=True), 2, " %")])
    rows.append(["<i>paper (nonlinear / linear)</i>", "—", PAPER["fit"], "—", PAPER["validation"],
                 "—", f"{PAPER['cooldown_nonlinear']} / {PAPER['cooldown_linear']}"])
    main = _table(("model", "fit RMSE", "fit NRMSE", "validation RMSE", "validation NRMSE",
                   "mean NRMSE over the long cool-downs", "flywheel alone (Fig. 5's temperature)"), rows)
    per = _table(["cool-down (cycle)", "set-points"] + [f"NRMSE {m}" for m in figures] + [f"RMSE {m}" for m in figures],
                 [[str(c.cycle), html.escape(c.description)] + [_num(c.nrmse_pct[m], 2, " %") for m in figures]
                  + [_num(c.rmse_k[m], 3, " K") for m in figures] for c in cooldowns])
    return main + "<h3>Per long cool-down of the validation run (as in Fig. 5)</h3>" + per


def _truth_section(params: ModelParams, truth: Mapping[str, float], standard_errors: Mapping[str, float]) -> str:
    """The identified parameters against the plant's truth: error, and error over the standard error where the runs
    identify the parameter (else why not, in the ± SE cell)."""
    rows = []
    reasons = recorded(params)
    for name, value in params.items():
        if name not in truth:
            continue
        true = float(truth[name])
        se = standard_errors.get(name, math.nan) if name not in reasons else math.nan
        rows.append([f"<code>{html.escape(name)}</code>", f"{value:.6g}",
                     html.escape(error_cell(se, reasons.get(name))), f"{true:.6g}",
                     _num(100 * (value - true) / true if true else math.nan, 2, " %"),
                     _num(abs(value - true) / se if se and se > 0 else math.nan, 1)])
    return _table(("parameter", "identified", "± SE", "plant truth", "error", "error / SE"), rows)


def _not_identified_section(params: ModelParams) -> str:
    """The nonlinear model's parameters the runs do not identify, each with its value, why and what would identify
    it ("" where the runs identify every one)."""
    reasons = recorded(params)
    items = "".join(f"<li><code>{html.escape(name)}</code> = {params[name]:.4g}: {html.escape(why)}</li>"
                    for name, why in reasons.items())
    return (f"<p>Not identified by these runs ({len(reasons)} of the {params.model} model's parameters: their "
            f"values are where the fit stopped, not measurements):</p><ul>{items}</ul>") if reasons else ""


def _story_sections(story: Mapping[str, Any]) -> list[str]:
    """Misfit at the peaks, extrapolation and the plate against truth (benchlab.report.showcase), the paper beside."""
    peaks = story["peaks"]
    models = list(next(iter(peaks.values())))
    rows = [[html.escape(run), m, _num(peaks[run][m].max_k, 2, " K"), _num(peaks[run][m].mean_k, 2, " K"),
             _num(peaks[run][m].max_pct, 1, " %"), str(peaks[run][m].peaks)] for run in peaks for m in models]
    rows.append(["<i>paper</i>", "nonlinear", "—", "—", "up to 5 %", "—"])
    out = ["<h3>Misfit at the heating peaks (the paper: up to 5 %, from the first-order structure)</h3>",
           _table(("run", "model", "largest |error|", "mean |error|", "largest, % of the peak's reading", "peaks"), rows)]
    extra = story["extrapolation"]
    out += ["<h3>Extrapolation: load scenarios the identification run did not have</h3>",
            "<p>The validation run ends with launches outside Table 1 (engine speeds, clutch and load torques it never "
            "drew). RMSE on those samples against the Table 1 cycles of the same run; the paper: the model is only "
            "accurate for load scenarios that are part of the identification data.</p>",
            _table(["samples"] + [f"RMSE {m}" for m in models],
                   [[html.escape(k)] + [_num(v[m], 3, " K") for m in models] for k, v in extra.items()])]
    plate = story.get("plate")
    if plate is not None:
        out += ["<h3>The unmeasured pressure plate against the plant's truth (validation run)</h3>",
                _table(("estimate", "RMSE", "largest |error|"),
                       [[html.escape(k), _num(plate.rmse_k[k], 2, " K"), _num(plate.max_k[k], 2, " K")]
                        for k in plate.rmse_k]),
                f"<p>While slipping the plate is {_num(plate.hotter_truth_k, 2, ' K')} hotter than the flywheel in "
                f"truth, {_num(plate.hotter_model_k, 2, ' K')} by the model (the paper: ϑ_P ≈ ϑ_F assumed, "
                "“slightly higher” expected).</p>"]
        if plate.band is not None:
            out.append(_plate_band(plate.band))
    return out


def _plate_band(band: "PlateBand") -> str:
    """The observer's ±2σ band of the plate against the truth (benchlab.report.showcase.PlateBand)."""
    text = (f"<p>The observer's ±2σ band, widened by the spread of the plate across the parameter sets the "
            f"identification holds plausible, across structures that fit as well, and by the sweep's reading of the "
            f"plate against the model's (docs/observer.md), covers the truth "
            f"{_num(100 * band.plate_band_coverage, 1, ' %')} of the samples (target ≥ 85 %), mean half-width "
            f"{_num(band.half_width_k, 2, ' K')}; the filter's band alone {_num(band.filter_half_width_k, 2, ' K')}.")
    if band.observer_note:
        text += f" <b>Note:</b> {html.escape(band.observer_note)}."
    return text + "</p>"


def _wear_band(band: "PlateBand") -> str:
    """Wear per side at the observer's estimate with its band against the wear at the truth's temperatures."""
    rows = [[side, _num(1000 * e, 4, " µm"), f"{_num(1000 * lo, 4)} – {_num(1000 * hi, 4, ' µm')}",
             _num(1000 * band.truth_wear_mm[side], 4, " µm"), "yes" if band.wear_covered(side) else "<b>no</b>"]
            for side, (e, lo, hi) in band.wear_mm.items()]
    return ("<p>The same wear law at the observer's estimate, over its ±2σ band (every sample at the same side of "
            "it: a model's error lasts), against the law at the plant's true temperatures (same friction power "
            "and heat split; Table 1 run):</p>"
            + _table(("side", "wear at the estimate", "over the ±2σ band", "at the truth", "within the band"), rows))


def _signal_mechanism(finding: dict) -> str:
    """A finding's signal and mechanism as the index shows them, HTML-escaped; the mechanism alone where it has no
    signal (a change of the structure)."""
    mechanism = html.escape(str(finding["mechanism"]))
    return f"{html.escape(str(finding['signal']))} / {mechanism}" if finding.get("signal") else mechanism


def _unseen_gain(finding: Mapping[str, Any]) -> str:
    """A finding's gain on the validation run, first in its line (empty where the diagnosis had no unseen run)."""
    gain = finding.get("unseen_gain_pct")
    return "" if gain is None else f"gain on the validation run (unseen) {_num(gain, 0, ' %')}, "


def _diagnosis_alternatives(findings: Sequence[Mapping[str, Any]]) -> str:
    """What the data cannot tell apart from each finding, and the measurement that would."""
    items = [f"<li>{html.escape(f['candidate'])} or {html.escape(a['candidate'])} (gain "
             f"{_num(a['gain_pct'], 0, ' %')}): {html.escape(str(a.get('tell_apart_by', '')))}</li>"
             for f in findings for a in f.get("alternatives", [])]
    return ("<p>Cannot be told apart on this data:</p><ul>" + "".join(items) + "</ul>") if items else \
        "<p>No alternative explains the data as well as a finding.</p>"


def _identified_by(pinned: Mapping[str, Sequence[str]]) -> str:
    """Which runs identify each parameter of the diagnosed model (benchlab.identify.uncertainty.identified_by_runs)."""
    groups: dict[str, list[str]] = {}
    for name, runs in pinned.items():
        groups.setdefault(" and ".join(runs) if runs else "none of the runs (not identified)", []).append(name)
    rows = [[html.escape(runs), html.escape(", ".join(names))] for runs, names in groups.items()]
    return ("<p>Which run identifies each parameter of the best model (alone, by the fit's covariance from that "
            "run's part):</p>" + _table(("identified by", "parameters"), rows))


def _deployed(proof: Mapping[str, Any]) -> str:
    """Section 5: the nonlinear model's observer and wear as C (benchlab deploy) and its proof on the validation run."""
    name = html.escape(proof["module"])
    worst = max(proof["max_abs_dev_K"].values())
    return ("<h2>5. The observer and the wear as C for a control unit</h2>"
            f"<p>The nonlinear model, its observer (T_air) and the wear per side as a C99 module in float "
            f"(<a href='deploy/{name}.c'>{name}.c</a>, <a href='deploy/{name}.h'>{name}.h</a>, "
            f"<a href='deploy/README.md'>README</a>), run over the validation run sample by sample beside benchlab's "
            f"observer: largest temperature deviation {_num(worst * 1000, 3, ' mK')}, plate σ "
            f"{_num(proof['plate_sigma_rel_dev'] * 100, 4, ' %')}, wear "
            f"{_num((proof['wear_rel_dev'] or 0.0) * 100, 4, ' %')} relative; {proof['state_bytes']} bytes of state, "
            f"{proof['code_bytes']} bytes of code, {_num(proof['step_us'], 2, ' µs')} per 10 ms step on this machine "
            f"(<a href='deploy/verify.json'>verify.json</a>; benchlab's docs/deploy.md).</p>")


def _wear_sides(wear: Mapping[str, Any]) -> str:
    rows = [[side, _num(v["energy_J"] / 1e6, 3, " MJ"), _num(v["mean_lining_temperature_C"], 1, " °C"),
             _num(v["max_lining_temperature_C"], 1, " °C"), _num(1000 * v["wear_run_mm"], 3, " µm")]
            for side, v in sorted(wear["wear"].items(), key=lambda item: item[0] != "plate")]
    return _table(("side", "friction energy", "mean lining temperature (energy-weighted)", "max", "wear this run"),
                  rows)


def write_index(out: "str | os.PathLike[str]", runs: Mapping[str, tuple[Path, pd.DataFrame]],
                identification: Mapping[str, Mapping[str, Mapping[str, float]]], cooldowns: Sequence[Cooldown],
                nonlinear: ModelParams, standard_errors: Mapping[str, float], diagnosis: Mapping[str, Any],
                wear: Mapping[str, Any], story: Mapping[str, Any] | None = None) -> Path:
    """Write `index.html` in `out` from the job's results; the figures are linked where the job wrote them.
    `story`: the misfit at the peaks, extrapolation and plate figures of benchlab.report.showcase, and the verdict."""
    out = Path(out)
    fitting_path = next(iter(runs.values()))[0]
    attrs = load_attrs(fitting_path)
    truth = json.loads(attrs["sim_truth"]) if "sim_truth" in attrs else None
    simulated = attrs.get("bench") == SIMULATED
    findings = diagnosis.get("findings", [])
    found = "".join(f"<li><b>{html.escape(f['candidate'])}</b> ({_signal_mechanism(f)}): {_unseen_gain(f)}held-out gain "
                    f"{_num(f['gain_pct'], 0, ' %')}, p = {f.get('p_value', math.nan):.2g}</li>"
                    for f in findings) or "<li>none</li>"
    found += "".join(f"<li>lead, not a cause: {html.escape(f['candidate'])} ({_signal_mechanism(f)}): "
                     f"{html.escape('; '.join(f['reasons']))}</li>"
                     for f in diagnosis.get("leads", []))
    base, best = diagnosis["baseline"], diagnosis["best"]
    unseen = best.get("unseen")
    life, health = wear["life"], wear["health"]
    p50 = life["engagements"].get("p50")
    reference = truth is not None and truth.get("plant", "paper") != "paper"
    plant_text = ("a reference dry clutch richer than the model (docs/plant.md: two-mass flywheel, plate coupled "
                  "through the lining, cover, housing and gearbox, radiation, μ(ϑ)); the numbers say what the paper's "
                  "model achieves on a plant it cannot match exactly" if reference else
                  "the paper's nonlinear clutch model"
                  + (f" (effects added to it: {', '.join(truth.get('effects', [])) or 'none'})" if truth else "")
                  + ". The numbers say how well benchlab recovers a known plant, not how a real clutch behaves")
    sections = [
        "<h1>benchlab: the whole job</h1>",
        *([f"<p><b>{html.escape(story['verdict'])}</b></p>"] if story and story.get("verdict") else []),
        "<p class='sim'>" + ("<b>Everything on this page comes from the simulated bench</b> (<code>sim_bench</code>): "
                             f"the drivers talked to emulated devices whose plant is {plant_text}."
                             if simulated else f"Measured on {html.escape(bench_text(attrs.get('bench'), simulated=attrs.get('bench_simulated', '')))}.")
        + "</p>",
        "<h2>1. The runs</h2>", _run_section(runs, out),
        _figure(out, out / "report" / "fig4_fit.png", "Fig. 4: the nonlinear model against the Table 1 run"),
        "<h2>2. Identification: linear against nonlinear (eq. 6–11)</h2>",
        "<p>NRMSE = 100 · RMSE / (max − min of the measured channel), averaged over ϑ_F, ϑ_A, ϑ_T (benchlab's docs/contract.md §5). "
        "The paper's percentages are its own error measure on its own bench; they are shown for orientation.</p>",
        _identify_section(identification, cooldowns),
        _not_identified_section(nonlinear),
    ]
    sections += [_figure(out, p, f"Fig. 5: validation {i}")
                 for i, p in enumerate(sorted((out / "report").glob("fig5_validation_*.png")), 1)]
    sections.append(_figure(out, out / "report" / "fig3_resistance.png", "Fig. 3: convection resistance R(ω_e, S)"))
    if story:
        sections += _story_sections(story)
    if truth is not None and not reference:
        sections += ["<h3>The nonlinear model against the simulated plant's truth</h3>",
                     _truth_section(nonlinear, truth.get("params", {}), standard_errors)]
    sections += [
        "<p>The full report with parameters, residual tests and error tables: <a href='report/report.html'>"
        "report/report.html</a> (as Markdown: <a href='report/report.md'>report/report.md</a>).</p>",
        f"<h2>3. What diagnose found ({html.escape(str(base.get('model', '')))} baseline"
        + (f", fitted on {html.escape(' and '.join(story['diagnosed_runs']))} together" if story and
           story.get("diagnosed_runs") else "") + ")</h2>",
        *([_identified_by(story["identified_by"])] if story and story.get("identified_by") else []),
        f"<p>Best model <b>{html.escape(str(best['model']))}</b>: "
        + (f"on the validation run (unseen) {_num(unseen['rmse_before_K'], 3, ' K')} → "
           f"{_num(unseen['rmse_after_K'], 3, ' K')}; " if unseen else "")
        + f"held-out RMSE {_num(base['rmse_K'], 3, ' K')} → {_num(best['rmse_K'], 3, ' K')}.</p><ul>{found}</ul>",
        _diagnosis_alternatives(findings),
        '<p>Evidence, regimes and figures: <a href="diagnose/diagnose.html">diagnose/diagnose.html</a> (as '
        'Markdown: <a href="diagnose/diagnose.md">diagnose/diagnose.md</a>), JSON: '
        '<a href="diagnose.json">diagnose.json</a>.</p>',
        "<h2>4. Wear (eq. 1–3) from the estimated lining temperatures</h2>",
        f"<p>{wear['engagements']} engagements, {_num(wear['friction_energy_J'] / 1e6, 2, ' MJ')} of friction "
        f"energy; health {_num(health['health'], 4)} ({'WORN' if health['worn'] else 'ok'}); remaining life "
        f"P50 {_num(p50, 0) if p50 is not None else 'beyond the horizon'} engagements; "
        f"P(worn within {life['horizon_engagements']}) = {_num(life['p_fail_within_horizon'], 3)}.</p>",
        _wear_sides(wear),
        *([_wear_band(story["wear_band"].band)] if story and story.get("wear_band") is not None else []),
        _figure(out, out / "wear.png", "Energy, lining temperatures, wear per side and remaining-life distribution"),
        '<p>All numbers: <a href="wear.json">wear.json</a>.</p>',
        *([_deployed(story["deploy"])] if story and story.get("deploy") else []),
    ]
    page = out / PAGE
    write_text(page, "<!DOCTYPE html><html><head><meta charset='utf-8'><title>benchlab: the whole job</title>"
                    f"<style>{STYLE}</style></head><body>{''.join(sections)}</body></html>")
    return page
