"""The report page: Markdown tables of error figures, parameters, cool-downs and residual tests, figures embedded."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

import benchlab
from benchlab.identify.cooldown import COVERAGE_K, CooldownResult
from benchlab.identify.identifiability import recorded
from benchlab.identify.metrics import RESIDUAL_LABEL
from benchlab.model.params import ModelParams
from benchlab.provenance import bench_text
from benchlab.report.markdown import literal, text
from benchlab.report.plotting import run_name
from benchlab.report.resistance import resistance, standard_errors
from benchlab.report.residuals import Residuals
from benchlab.report.scores import Estimate
from benchlab.units import display

SYMBOLS = {"T_flywheel": "ϑ_F", "T_air": "ϑ_A", "T_housing": "ϑ_T"}


def channel_cell(channel: str) -> str:
    """A measured channel in a table: the clutch's symbol and the channel name."""
    return f"{SYMBOLS[channel]} `{channel}`" if channel in SYMBOLS else literal(channel)


@dataclass(frozen=True)
class Figures:
    """The report's PNGs, all in the page's directory."""

    fit: Path
    validation: list[Path]
    resistance: Path | None  # Fig. 3, for clutch models with eq. (11) only
    residuals: Path


def number(value: float, digits: int) -> str:
    """A table cell: the value with `digits` decimals, or an em dash where it is not a finite number."""
    return f"{value:.{digits}f}" if isinstance(value, (int, float)) and math.isfinite(value) else "—"


def table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


def unit(name: str, models: Sequence[tuple[str, ModelParams]] = ()) -> str:
    """The unit of a parameter (as Markdown text): as its model file gives it, else the contract's (section 2)."""
    given = next((p.definition.parameters[name].unit for _, p in models if name in p.definition.parameters), "")
    if given:
        return text(display(given))
    if name.startswith("C_"):
        return "J/K"
    if name.startswith("R") or name in ("a1", "a2"):
        return "K/W"
    return "1/rpm" if name in ("b1", "b2") else "(extension)"


def scores_table(rows: Sequence[tuple[pd.DataFrame, Estimate]]) -> str:
    """RMSE (K) and NRMSE (%) per run, model and channel, then over all channels (contract section 5)."""
    cells = []
    for run, est in rows:
        s = est.scores
        for c in est.channels:
            cells.append((literal(run_name(run)), text(est.label), channel_cell(c), number(s.channel_rmse_k[c], 4),
                          number(s.channel_nrmse_pct[c], 3)))
        cells.append((literal(run_name(run)), text(est.label), "**all** (§5)", number(s.rmse_k, 4),
                      number(s.nrmse_pct, 3)))
    return table(("run", "model", "channel", "RMSE (K)", "NRMSE (%)"), cells)


def params_table(models: Sequence[tuple[str, ModelParams]]) -> str:
    """Each model's parameter values with their standard errors where the file holds them, or why the runs do not
    identify them."""
    names = list(dict.fromkeys(name for _, params in models for name in params))
    header = ["parameter", "unit"] + [h for label, _ in models for h in (text(label), "± SE")]
    unidentified = [recorded(params) for _, params in models]
    cells = []
    for name in names:
        row = [literal(name), unit(name, models)]
        for (_, params), reasons in zip(models, unidentified):
            row += [f"{params[name]:.6g}" if name in params else "—",
                    error_cell(standard_errors(params).get(name, math.nan), reasons.get(name))]
        cells.append(row)
    return table(header, cells)


def error_cell(error: float, not_identified: str | None) -> str:
    """A parameter's ± SE cell: "not identified: why" where the runs do not identify it (its standard error says
    nothing), else the standard error, or an em dash where the file has none."""
    if not_identified is not None:
        return text(f"not identified: {not_identified}")
    return f"{error:.2g}" if math.isfinite(error) else "—"


def cooldown_table(cooldowns: Sequence[CooldownResult], models: Sequence[tuple[str, ModelParams]]) -> str:
    """Per cool-down: operating point, fitted R ± U and each model's eq. (11) at that point."""
    header = ["cycle", "ω_e (rpm)", "S", "R fitted (K/W)", f"± U, k = {COVERAGE_K:g} (K/W)"]
    header += [f"R {text(label)} (K/W)" for label, _ in models]
    cells = []
    for r in cooldowns:
        row = [str(r.cycle), number(r.engine_speed, 0), str(r.clutch_state), number(r.R, 4), number(r.R_u, 4)]
        row += [number(float(resistance(p, np.array([r.engine_speed]), r.clutch_state)[0][0]), 4) for _, p in models]
        cells.append(row)
    return table(header, cells)


def residual_table(res: Residuals) -> str:
    """Identify's residual tests: share of autocorrelations outside the 99 % bound, the verdict on window means
    (Ljung–Box p, structure in K against its threshold), strongest input correlations."""
    inputs = list(res.inputs)
    header = ["channel", "samples", "ACF outside ±2.58/√N, lags 1–50 (%)", "Ljung–Box p (window means)",
              "structure (K)", "white"] + [f"corr. with {literal(k)}" for k in inputs]
    cells = []
    for c, t in res.tests.items():
        row = [channel_cell(c), str(t["samples"]), number(t["whiteness_outside_pct"], 1), number(t["ljung_box_p"], 3),
               f"{number(t['structure_K'], 3)} (limit {number(t['effect_threshold_K'], 2)})",
               "yes" if t["white"] else "no"]
        cells.append(row + [number(t["input_correlation"][k], 2) for k in inputs])
    return table(header, cells)


def render(run: pd.DataFrame, models: Sequence[tuple[str, ModelParams]],
           rows: Sequence[tuple[pd.DataFrame, Estimate]], figures: Figures,
           cooldowns: Sequence[CooldownResult], cooldowns_source: str, res: Residuals) -> str:
    """The whole page: error figures, parameters, Fig. 4, Fig. 5, Fig. 3 (with the sweep's cool-downs, introduced
    by `cooldowns_source`: where they come from), residuals."""
    duration = float(run["time"].iloc[-1] - run["time"].iloc[0])
    models_text = ", ".join(f"**{text(label)}** ({literal(params.model)})" for label, params in models)
    parts = [
        f"# benchlab report – {literal(run_name(run))}",
        f"Run {literal(run.attrs.get('source', ''))} from **{text(bench_text(run.attrs.get('bench'), simulated=run.attrs.get('bench_simulated', '')))}**: protocol "
        f"{literal(run.attrs.get('protocol', ''))}, {duration:.0f} s at a "
        f"step of {float(run.attrs['dt']):g} s, {len(run)} samples. Models: {models_text}. "
        f"Written by benchlab {benchlab.__version__}.",
        "## Error figures (benchlab's docs/contract.md §5)",
        "RMSE in K over the valid samples; NRMSE = 100 · RMSE / (max − min of the measured channel), "
        f"for **all** averaged over {', '.join(channel_cell(c) for c in rows[0][1].channels)}. The model is driven by "
        "the run's measured inputs from the "
        "first valid measured temperatures (`benchlab simulate`).",
        scores_table(rows),
        "## Parameters",
        "Standard errors as the parameter file's `uncertainty` holds them (from `benchlab identify`); a parameter "
        "the runs do not identify shows why and what would identify it instead (its `not_identified`).",
        params_table(models),
        "## Fig. 4 – measured and estimated temperatures",
        f"![Fig. 4]({figures.fit.name})",
        "## Fig. 5 – validation: " + " against ".join(text(label) for label, _ in models),
        *[f"![Fig. 5]({p.name})" for p in figures.validation],
    ]
    if figures.resistance is not None:
        parts += ["## Fig. 3 – convection resistance against engine speed", f"![Fig. 3]({figures.resistance.name})"]
    if cooldowns:
        parts += [cooldowns_source, cooldown_table(cooldowns, models)]
    parts += [
        f"## Residual analysis – {text(res.label)} model on {literal(res.run)}",
        f"Residual = {RESIDUAL_LABEL} at the identification step of {res.step_s:g} s, the model started from the "
        "temperatures that fit the run best with its parameters held (`benchlab identify`'s residual tests: a channel "
        "is not white when its 60 s means are autocorrelated or hold more than the white noise's share, at 1 %, and "
        "their structure exceeds the effect threshold in kelvin; docs/report.md).",
        f"![Residuals]({figures.residuals.name})",
        residual_table(res),
    ]
    return "\n\n".join(parts) + "\n"
