"""What one batch task computes on a worker: its runs loaded, fitted, diagnosed or analysed, rows out.

A task never raises for its runs' sake: a run that cannot be read is a row with its error and the task
goes on with the others; a fit that fails makes every run it covered a failed row. Per-task files
(parameter file, diagnose JSON, wear JSON) are written into the output directory, which the workers
must see at the same path as the client (a shared file system on a real cluster).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from benchlab.batch import adapter
from benchlab.errors import InputError
from benchlab.outputs import write_text

OK, FAILED = "ok", "failed"
#: The run attribute that dates a run (written by `benchlab run`); trends use it as their time axis.
TIME_ATTR = "created_utc"
SE_SUFFIX = "_se"


@dataclass(frozen=True)
class Job:
    """What every task of one batch shares."""

    kind: str
    model: str
    out_dir: str
    starts: int
    seed: int
    params_path: str | None = None  # wear: one parameter file for every run instead of a fit per task


@dataclass(frozen=True)
class RunRef:
    """A run of the batch: its position in the batch's sorted order (the trends' run index), path, unique name."""

    index: int
    path: str
    name: str


@dataclass(frozen=True)
class Task:
    """One unit of work: runs that belong together (one, or a group), named for its files."""

    name: str
    runs: tuple[RunRef, ...]
    group: str | None = None  # the value of --group-by's attribute the runs share

    @property
    def index(self) -> int:
        """The position of its first run."""
        return self.runs[0].index


def error_text(exc: BaseException) -> str:
    """One line for the table: bad input as its own message, anything else with its type."""
    text = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


def failed_row(task: Task, runs: str, error: str, index: int | None = None) -> dict:
    """A row for runs that produced no result."""
    return {"task": task.name, "group": task.group, "index": task.index if index is None else index, "run": runs,
            "status": FAILED, "error": error}


def parameter_columns(params: dict[str, float], errors: dict[str, float]) -> dict[str, float]:
    """Each parameter and, where fitted, its standard error in `NAME_se`."""
    out: dict[str, float] = {}
    for name, value in params.items():
        out[name] = float(value)
        if name in errors:
            out[name + SE_SUFFIX] = float(errors[name])
    return out


@dataclass(frozen=True)
class Loaded(RunRef):
    """A task's run that could be read, with its channels."""

    frame: pd.DataFrame


def _load(job: Job, task: Task) -> tuple[list[Loaded], list[dict]]:
    """The task's readable runs, each checked for the model it is read for; a failed row for each unreadable one."""
    loaded, failures = [], []
    for ref in task.runs:
        try:
            model = adapter.read_params(job.params_path).definition if job.params_path else adapter.model_of(job.model)
            loaded.append(Loaded(ref.index, ref.path, ref.name, adapter.read_run(ref.path, model)))
        except Exception as exc:  # noqa: BLE001 - a bad run is a row, never a lost batch
            failures.append(failed_row(task, ref.path, error_text(exc), ref.index))
    return loaded, failures


def _joined(runs: Sequence[Loaded]) -> str:
    return ";".join(r.path for r in runs)


def _created(path: str) -> str | None:
    """The run's creation time (root attribute), if it has one."""
    return adapter.read_attrs(path).get(TIME_ATTR)


def _identify(job: Job, task: Task, runs: list[Loaded]) -> list[dict]:
    result = adapter.fit([r.frame for r in runs], adapter.model_of(job.model), job.starts, job.seed)
    out = Path(job.out_dir) / f"{task.name}.params.json"
    adapter.save_fit(out, result)
    params, errors = adapter.fitted(result)
    return [{"index": runs[0].index, "run": _joined(runs), "runs": len(runs), "created": _created(runs[0].path),
             "model": job.model, "params_file": str(out), **parameter_columns(params, errors), **adapter.fit_figures(result)}]


def _diagnose(job: Job, task: Task, runs: list[Loaded]) -> list[dict]:
    result = adapter.diagnosis([r.frame for r in runs], adapter.model_of(job.model), job.seed)
    out = Path(job.out_dir) / f"{task.name}.diagnose.json"
    adapter.save_diagnosis(out, result)
    findings = result["findings"]
    return [{"index": runs[0].index, "run": _joined(runs), "runs": len(runs), "created": _created(runs[0].path),
             "model": job.model, "diagnose_file": str(out),
             "baseline_rmse_K": result["baseline"]["rmse_K"], "baseline_nrmse_pct": result["baseline"]["nrmse_pct"],
             "best_model": result["best"]["model"], "best_rmse_K": result["best"]["rmse_K"],
             "best_nrmse_pct": result["best"]["nrmse_pct"], "findings": len(findings),
             "finding_summaries": "; ".join(f"{f['mechanism']}/{f['signal']}: {f['summary']} "
                                            f"(gain {f['gain_pct']:.1f} %)" for f in findings)}]


def wear_columns(doc: dict) -> dict[str, object]:
    """The wear JSON's headline figures as table columns (wear in micrometres)."""
    life, health = doc["life"], doc["health"]
    return {"friction_energy_J": doc["friction_energy_J"], "engagements": doc["engagements"],
            "slip_time_s": doc["slip_time_s"], "split": doc["split"],
            **{f"wear_{side}_um": 1e3 * s["wear_run_mm"] for side, s in doc["wear"].items()},
            "health": health["health"], "worn": health["worn"],
            "life_p50_engagements": life["engagements"]["p50"], "p_fail_within_horizon": life["p_fail_within_horizon"]}


def _wear(job: Job, task: Task, runs: list[Loaded]) -> list[dict]:
    """Wear of each run, with the given parameter file or with parameters fitted on the task's runs together."""
    if job.params_path is not None:
        params, source = adapter.read_params(job.params_path), job.params_path
        shared = parameter_columns(params, {})
    else:
        result = adapter.fit([r.frame for r in runs], adapter.model_of(job.model), job.starts, job.seed)
        source = str(Path(job.out_dir) / f"{task.name}.params.json")
        adapter.save_fit(source, result)
        params, errors = adapter.fitted(result)
        shared = {"model": job.model, **parameter_columns(params, errors), **adapter.fit_figures(result)}
    rows = []
    for run in runs:
        try:
            doc = adapter.wear(run.frame, params, source, job.seed)
        except Exception as exc:  # noqa: BLE001 - one run's failure is its row
            rows.append(failed_row(task, run.path, error_text(exc), run.index))
            continue
        out = Path(job.out_dir) / f"{run.name}.wear.json"
        write_text(out, json.dumps(doc, default=float))
        rows.append({"index": run.index, "run": run.path, "created": _created(run.path), "params_file": source,
                     "wear_file": str(out), **shared, **wear_columns(doc)})
    return rows


_KIND: dict[str, Callable[[Job, Task, list[Loaded]], list[dict]]] = {
    "identify": _identify, "diagnose": _diagnose, "wear": _wear}


def run_task(job: Job, task: Task) -> list[dict]:
    """The task's rows: one per task (identify, diagnose) or per run (wear), plus one per run that failed.

    Each row holds `status` ok/failed, `error`, and the task's wall and CPU seconds.
    """
    started, cpu = time.perf_counter(), time.thread_time()
    runs, rows = _load(job, task)
    if runs:
        try:
            done = _KIND[job.kind](job, task, runs)
        except Exception as exc:  # noqa: BLE001 - a failed fit is a row with its error
            done = [failed_row(task, _joined(runs), error_text(exc), runs[0].index)]
        rows.extend({"task": task.name, "group": task.group, "index": task.index, "status": OK, "error": "",
                     **row} for row in done)
    seconds, cpu_s = time.perf_counter() - started, time.thread_time() - cpu
    for row in rows:
        row.update(task_s=seconds, task_cpu_s=cpu_s)
    return rows
