"""The diagnosis as a readable page: what is wrong, where, why, what was added and how much better (diagnose.md, the
same page as diagnose.html, PNGs)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

import benchlab
from benchlab.diagnose.engine import ALPHA, Diagnosis
from benchlab.diagnose.evidence import has_signal
from benchlab.diagnose.figures import (WINDOW_S, measured_channels, plot_binned, plot_evidence, plot_gains,
                                       plot_regimes, plot_window, worst_window)
from benchlab.diagnose.regimes import MIN_REGIME_SAMPLES, worst_regimes
from benchlab.outputs import write_text
from benchlab.provenance import bench_text
from benchlab.report.html import write_html
from benchlab.report.markdown import literal, text
from benchlab.report.page import channel_cell, number, table, unit
from benchlab.report.plotting import run_name

PAGE = "diagnose.md"
EVIDENCE_ROWS = 15
def _rmse(entry: dict, channel: str) -> str:
    return number(entry["channels"][channel]["rmse_K"], 4)


def _what_is_wrong(summary: dict, regimes_png: Path) -> list[str]:
    base, best, reg = summary["baseline"], summary["best"], summary["regimes"]
    channels = measured_channels(reg)
    per_channel = [(channel_cell(c), str(reg["baseline"]["all"]["all"]["channels"][c]["samples"]),
                    _rmse(reg["baseline"]["all"]["all"], c), _rmse(reg["best"]["all"]["all"], c)) for c in channels]
    overall = reg["baseline"]["all"]["all"]["channels"]
    worst = [(text(g), literal(label), channel_cell(c), number(rmse, 4), number(rmse / overall[c]["rmse_K"], 2),
              _rmse(reg["best"][g][label], c), str(n)) for g, label, c, rmse, n in worst_regimes(reg["baseline"], 6)]
    full = [(text(g), literal(label), channel_cell(c), _rmse(entry, c), _rmse(reg["best"][g][label], c),
             str(entry["channels"][c]["samples"]))
            for g, labels in reg["baseline"].items() if g != "all" for label, entry in labels.items() for c in channels]
    return [
        "## What is wrong",
        f"The baseline model ({literal(base['model'])}) misses the measured temperatures by a held-out RMSE of "
        f"**{base['rmse_K']:.4f} K** ({base['nrmse_pct']:.2f} % NRMSE); the final model ({literal(best['model'])}) by "
        f"**{best['rmse_K']:.4f} K** ({best['nrmse_pct']:.2f} %). Held-out: {summary['method']['validation']}.",
        table(("channel", "samples", "baseline RMSE (K)", "final RMSE (K)"), per_channel),
        f"Worst regimes of the baseline (held-out residuals, regimes of at least {MIN_REGIME_SAMPLES} samples):",
        table(("group", "regime", "channel", "baseline RMSE (K)", "× channel's whole RMSE", "final RMSE (K)",
               "samples"), worst),
        f"Regimes: {summary['method']['regimes']}. `phase`: slipping (friction power > 0), locked (clamped, not "
        "slipping), open; slipping samples are in no cool-down; the flywheel has few samples while slipping (its "
        "1 s targets are skipped where their window holds slipping). — where a regime has no sample.",
        f"![Held-out RMSE by regime]({regimes_png.name})",
        "<details><summary>All regimes</summary>\n\n"
        + table(("group", "regime", "channel", "baseline RMSE (K)", "final RMSE (K)", "samples"), full)
        + "\n\n</details>",
    ]


def _where(result: Diagnosis, names: Sequence[str], window_png: Path) -> list[str]:
    run, start, stop = worst_window(result.baseline_held)
    dt = result.baseline_held.datasets[run].dt
    return [
        "## Where",
        f"The {WINDOW_S / 60:.0f} minutes with the largest baseline held-out error: run {literal(names[run])}, "
        f"minutes {start * dt / 60:.1f}–{stop * dt / 60:.1f}. Dots: measured; dashed: baseline, solid: final "
        "model, each sample predicted by the fold fit that did not see it.",
        f"![Worst window]({window_png.name})",
    ]


def _why(summary: dict, evidence_png: Path, finding_pngs: Sequence[tuple[dict, str, Path]]) -> list[str]:
    rows = summary["evidence"]
    significant = sum(r["p_value"] < ALPHA for r in rows)
    cells = [(str(i), literal(r["signal"]), text(r["kind"]), channel_cell(r["channel"]), text(r["form"]),
              number(r["explained_pct"], 1),
              number(r["shifted_pct"], 1), f"{r['p_value']:.3f}", str(r["samples"]))
             for i, r in enumerate(rows[:EVIDENCE_ROWS], 1)]
    parts = [
        "## Why",
        f"Evidence: {summary['method']['evidence']}. {significant} of {len(rows)} tests have p < {ALPHA:g} "
        f"(about {ALPHA * len(rows):.1f} would by chance alone). Signals that move together (engine and clutch "
        "speed while driving, temperatures and time) share the evidence: the table says what the residual "
        "follows, the extensions' held-out fits below decide the cause.",
        table(("rank", "signal", "kind", "channel", "form", "explained (%)", "shifted median (%)", "p", "samples"),
              cells),
        f"![Evidence]({evidence_png.name})",
    ]
    for f, signal, png in finding_pngs:
        parts += [f"### {text(f['summary'])}",
                  f"Baseline residual against {literal(signal)} before (without the extension) and after (with it): "
                  "binned means with 95 % intervals from block-robust standard errors (5-minute blocks).",
                  f"![{text(f['candidate'])}]({png.name})"]
    return parts


def _added(summary: dict) -> list[str]:
    parts = ["## What was added"]
    bounds = summary["method"]["baseline_bounds"]
    if bounds:
        parts += ["The baseline's fit leaves these parameters on a bound of the model file; each was held there while "
                  "the candidates were judged, so an extension is credited only with what it adds:",
                  table(("parameter", "value", "bound", "limit", "what to do"),
                        [(literal(b["parameter"]), f"{b['value']:.6g}", text(b["bound"]), f"{b['limit']:.6g}",
                          text(b["advice"]))
                         for b in bounds])]
    floor = summary["floor"]
    parts.append(f"Noise floor of the measurements (what a perfect model scores): **{floor['noise_K']:.4f} K**; the "
                 f"baseline is {floor['baseline_ratio']:.1f}x it, the final model {floor['best_ratio']:.1f}x: "
                 f"{floor['verdict']}.")
    if not summary["findings"]:
        parts.append("Nothing: no extension lowers the held-out error significantly, so the model is kept as it is.")
    for f in summary["findings"]:
        units = f.get("units", {})  # the extended model file's (library.py writes one for each parameter it adds)
        params = [(literal(k), f"{v:.6g}", text(units[k]) if units.get(k) else unit(k))
                  for k, v in f["params"].items()]
        signal = f"Signal {literal(f['signal'])}" if f["signal"] else "No signal (a change of the structure)"
        label = ("a cause" if f["label"] == "cause" else
                 f"a {f['label']}, not a cause ({text('; '.join(f['label_reasons']))})")
        parts += [f"**{text(f['candidate'])}** ({label}) – {text(f['summary'])}. {signal}, mechanism "
                  f"{literal(f['mechanism'])}: {literal(f['extension'])}",
                  table(("parameter", "value", "unit"), params)]
        parts += _ties(f, "Not")
    for lead in summary["leads"]:  # a lead is out of the final model (How much better), its tie still open
        parts += _ties(lead, f"The lead {literal(lead['candidate'])} is not")
    if any(f.get("alternatives") for f in summary["findings"] + summary["leads"]):
        parts.append("A sensor's place is worth what it removes of the pressure plate's estimate variance (the "
                     "Kalman observer of the model with the named extension, over the diagnosed runs' inputs; a place "
                     "measured now: what losing its sensor would add) and what its channel adds to the test statistic "
                     "between the two models on these runs (the sum over their samples of the squared difference of "
                     "the two models' predictions over the misfit of the better one, in effective samples; a new "
                     "sensor weighed against the worst measured misfit). `benchlab design RUN.h5 … --diagnosis "
                     "D.json` (this diagnosis as `--json`) designs the run that tells the first tie apart and says "
                     "which should lose by how much (docs/design.md).")
    return parts


def _ties(finding: dict, subject: str) -> list[str]:
    """Each alternative of a finding or lead (`subject` starts the sentence): the measurement that would tell the two
    apart, and where a sensor would (_sensor_places)."""
    return [f"{subject} told apart from {literal(a['candidate'])} (gain {a['gain_pct']:.0f} %): "
            f"{text(a['tell_apart_by'])}." + _sensor_places(a.get("sensors", []))
            for a in finding.get("alternatives", [])]


def _sensor_places(places: Sequence[dict]) -> str:
    """An alternative's sensor ranking (`sensors` of the diagnose JSON) in one sentence, best place first."""
    if not places:
        return ""
    said = [f"{literal(p['channel'])} (node {literal(p['node'])}, "
            f"{'measured now' if p['measured'] else 'no sensor now'})" for p in places]
    first = places[0]
    return (f" On these runs a sensor at {said[0]} would remove {number(first['plate_variance_reduction_pct'], 1)} % "
            f"of the plate's estimate variance and add {first['test_gain']:.3g} to the test statistic between the "
            "two" + "".join(f"; at {where}: {number(p['plate_variance_reduction_pct'], 1)} % and {p['test_gain']:.3g}"
                            for where, p in zip(said[1:], places[1:])) + ".")


def _unseen_cells(entry: dict) -> tuple[str, str]:
    """A finding's or the best model's RMSE before → after on the unseen runs and its gain; — without them."""
    unseen = entry["unseen"]
    if not unseen:
        return "—", "—"
    return (f"{number(unseen['rmse_before_K'], 4)} → {number(unseen['rmse_after_K'], 4)}",
            f"{number(unseen['gain_pct'], 1)} (p {unseen['p_value']:.2g})")


def _better(summary: dict, gains_png: Path) -> list[str]:
    heads = ("finding", "label", "signal", "unseen runs RMSE (K)", "unseen gain (%)", "held-out RMSE before (K)",
             "held-out RMSE after (K)", "held-out gain (%)", "p")
    cells = [(literal(f["candidate"]), text(f["label"]), literal(f["signal"]), *_unseen_cells(f),
              number(f["rmse_before_K"], 4), number(f["rmse_after_K"], 4), number(f["gain_pct"], 1),
              f"{f['p_value']:.2g}") for f in summary["findings"]]
    leads = [(literal(f["candidate"]), literal(f["signal"]), *_unseen_cells(f), number(f["gain_pct"], 1),
              text(f"{f['label']}: " + "; ".join(f["label_reasons"]))) for f in summary["leads"]]
    base, best = summary["baseline"], summary["best"]
    unseen = best["unseen"]
    together = (f"on the unseen runs {unseen['rmse_before_K']:.4f} K → {unseen['rmse_after_K']:.4f} K "
                f"({unseen['gain_pct']:.1f} % lower); " if unseen else "")
    return [
        "## How much better",
        f"Unseen runs (`--validate`): {summary['method']['unseen']}. Held-out: {summary['method']['gain']}. "
        f"Accepted at a gain of at least {summary['method']['min_gain_pct']:g} % and p < {summary['method']['alpha']:g} "
        f"(paired test over 5-minute blocks); {summary['method']['causes']}.",
        table(heads, cells) if cells else "",
        f"All together: {together}{base['rmse_K']:.4f} K → {best['rmse_K']:.4f} K held-out "
        f"({100 * (1 - best['rmse_K'] / base['rmse_K']):.1f} % lower).",
        ("Leads, not causes (they passed the held-out test but are not identified or do not carry to the unseen "
         "runs):\n\n" + table(("lead", "signal", "unseen runs RMSE (K)", "unseen gain (%)", "held-out gain (%)",
                                "why not a cause"), leads)) if leads else "",
        f"![Gains]({gains_png.name})",
    ]


def write_page(result: Diagnosis, summary: dict, runs: Sequence[pd.DataFrame],
               out_dir: "str | os.PathLike[str]") -> Path:
    """Write the figures and diagnose.md for a diagnosis and its summary (benchlab.diagnose.report.summarise)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = [run_name(r) for r in runs]
    finding_pngs = []
    for i, (finding, f) in enumerate(zip(result.findings, summary["findings"]), 1):
        signal = f["signal"]  # none: a change of the structure, no signal to bin the residual against
        if signal and has_signal(signal, finding.before.datasets[0].channels):
            finding_pngs.append((f, signal, plot_binned(finding.before, finding.after, signal,
                                                        out / f"finding_{i}_{signal}.png", f["summary"])))
    regimes_png = plot_regimes(summary["regimes"], out / "regimes.png")
    window_png = plot_window(result, names, out / "worst_window.png")
    evidence_png = plot_evidence(summary["evidence"], out / "evidence.png")
    gains_png = plot_gains(summary["regimes"], summary["findings"], out / "gains.png")
    parts = ["# benchlab diagnose – " + ", ".join(literal(n) for n in names),
             f"{len(runs)} run(s), {sum(len(d) for d in result.baseline_held.datasets)} samples at the fitting step "
             f"of {summary['method']['step_s']:g} s; baseline `{summary['baseline']['model']}`. "
             f"Written by benchlab {benchlab.__version__}.",
             "Measured on " + "; ".join(f"**{text(bench_text(bench))}** ({', '.join(literal(n) for n in runs_of)})"
                                        for bench, runs_of in _benches(runs, names).items()) + "."]
    parts += _what_is_wrong(summary, regimes_png)
    parts += _where(result, names, window_png)
    parts += _why(summary, evidence_png, finding_pngs)
    parts += _added(summary)
    parts += _better(summary, gains_png)
    page = out / PAGE
    write_text(page, "\n\n".join(p for p in parts if p) + "\n")
    write_html(page, "benchlab diagnose – " + ", ".join(names))
    return page


def _benches(runs: Sequence[pd.DataFrame], names: Sequence[str]) -> dict[str | None, list[str]]:
    """The runs' names by the bench that produced each (the run file's `bench` attribute)."""
    benches: dict[str | None, list[str]] = {}
    for run, name in zip(runs, names):
        benches.setdefault(run.attrs.get("bench"), []).append(name)
    return benches
