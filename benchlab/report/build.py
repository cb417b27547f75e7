"""write_report(): every figure and the page of `benchlab report` from loaded runs and parameter sets."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TypeVar
from pathlib import Path

import pandas as pd

from benchlab.identify.cooldown import CooldownResult, analyse, stored
from benchlab.errors import InputError
from benchlab.outputs import write_text
from benchlab.model.params import ModelParams
from benchlab.progress import SILENT, Progress
from benchlab.report.html import write_html
from benchlab.report.markdown import literal
from benchlab.report.page import Figures, render
from benchlab.report.plotting import run_name
from benchlab.report.residuals import plot_residuals, residuals
from benchlab.report.resistance import has_convection_law, plot_resistance
from benchlab.report.scores import estimate
from benchlab.report.timeseries import plot_comparison, plot_fit

T = TypeVar("T")

PAGE = "report.md"


def model_labels(params: ModelParams, compare: ModelParams | None) -> list[tuple[str, ModelParams]]:
    """(label, parameters) of the report's models: their kind, told apart when both are of one kind."""
    if compare is None:
        return [(params.model, params)]
    if compare.model == params.model:
        return [(f"{params.model} (params)", params), (f"{compare.model} (compare)", compare)]
    return [(params.model, params), (compare.model, compare)]


def sweep_cooldowns(sweep: "str | os.PathLike[str]", params: ModelParams, progress: Progress = SILENT,
                    fitted: Sequence[CooldownResult] | None = None) -> tuple[list[CooldownResult], str]:
    """Every cool-down of a cooldown-sweep run and where the page says they come from: the run file's /analysis
    as `benchlab cooldown` stored it, else fitted with the other parameters of `params` (`fitted`: the caller's own
    benchlab.identify.cooldown.analyse(sweep, params), not fitted a second time)."""
    analysed = stored(sweep)
    if analysed is not None and analysed.results:
        source = (literal(analysed.params_source) if analysed.params_source
                  else "a parameter file not named in the run")
        return analysed.results, (f"Cool-downs of the sweep as `benchlab cooldown` stored them in the run file's "
                                  f"`/analysis` (fitted with the other parameters of {source}):")
    results = list(fitted) if fitted is not None else analyse(sweep, params, progress=progress)
    return results, ("Cool-downs of the sweep, fitted here with the other parameters of the first model (the run "
                     "file has no `/analysis`: `benchlab cooldown` stores one):")


def write_report(run: pd.DataFrame, params: ModelParams, out_dir: "str | os.PathLike[str]",
                 compare: ModelParams | None = None, validation: Sequence[pd.DataFrame] = (),
                 sweep: "str | os.PathLike[str] | None" = None, progress: Progress = SILENT,
                 sweep_fitted: Sequence[CooldownResult] | None = None) -> Path:
    """Write Fig. 4, Fig. 5 (per validation run, else on `run`), Fig. 3, the residual figure, report.md and the same
    page as report.html.

    `run` and `validation` are loaded run files (benchlab.load_run), `sweep` the path of a cooldown-sweep
    run file (its events mark the cool-downs), `sweep_fitted` its cool-downs where the caller already fitted them
    with `params` (sweep_cooldowns). Returns the page's path.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    models = model_labels(params, compare)
    convection = all(has_convection_law(p) for _, p in models)
    if sweep is not None and not convection:
        raise InputError(sweep, "--sweep", "a report of clutch models (eq. 11): the cool-down sweep fits R_FA = R_PA")
    cooldowns, cooldowns_source = (sweep_cooldowns(sweep, params, progress, sweep_fitted) if sweep is not None
                                   else ([], ""))
    with progress.task("report", len(models) * (1 + len(validation)) + 2 + convection + max(len(validation), 1),
                       unit="step") as task:
        def step(value: T) -> T:
            task.advance()
            return value

        on_run = [step(estimate(run, p, label)) for label, p in models]
        checks = [(v, [step(estimate(v, p, label)) for label, p in models]) for v in validation] or [(run, on_run)]
        res = residuals(run, on_run[0], params)
        figures = Figures(
            fit=step(plot_fit(run, on_run[0], out / "fig4_fit.png")),
            validation=[step(plot_comparison(v, ests, out / f"fig5_validation_{i}.png"))
                        for i, (v, ests) in enumerate(checks, 1)],
            resistance=step(plot_resistance(models, cooldowns, out / "fig3_resistance.png")) if convection else None,
            residuals=step(plot_residuals(res, out / "residuals.png")),
        )
    rows = [(run, e) for e in on_run] + [(v, e) for v, ests in checks if v is not run for e in ests]
    page = out / PAGE
    write_text(page, render(run, models, rows, figures, cooldowns, cooldowns_source, res))
    write_html(page, f"benchlab report – {run_name(run)}")
    return page
