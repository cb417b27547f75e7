"""`benchlab batch identify|diagnose|wear RUN_GLOB… --out DIR [--model M] [--scheduler ADDRESS] [--group-by ATTR]`.

Many runs on dask.distributed (the optional extra `.[cluster]`): one task per run or per group of runs,
a local loopback-only cluster by default, one results table plus per-run files and trends in DIR.
Exit 0 when every run succeeded, 1 when the table was written but some runs failed (rows with their
error), 2 for bad usage (dask not installed, a glob matching nothing, a scheduler that does not answer).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchlab import cliargs
from benchlab.batch.cluster import EXTRA, Connection, connect, require_distributed
from benchlab.batch.kinds import DEFAULT_MODEL, KINDS
from benchlab.bounds import MAX_FIT_STARTS, MAX_LOCAL_WORKERS, MAX_TIMEOUT_S
from benchlab.diagnose.parallel import workers
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from benchlab.model.names import MODEL_HELP
from benchlab.outputs import check_output_dir, write_text
from benchlab.progress import for_terminal

NAME = "batch"
HELP = "identify, diagnose or analyse wear of many runs on a dask cluster (local by default); one results table"
FILES = {"identify": "TASK.params.json", "diagnose": "TASK.diagnose.json",
         "wear": "RUN.wear.json (and TASK.params.json without --params)"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("kind", choices=KINDS, help="what to do with each run (or group)")
    parser.add_argument("runs", nargs="+", metavar="RUN_GLOB",
                        help="run files or quoted globs ('runs/**/*.h5'); ordered by path, numbers as numbers")
    parser.add_argument("--out", required=True, metavar="DIR", help="directory for the table, trends and per-run files")
    parser.add_argument("--model", metavar="MODEL",
                        help=f"{MODEL_HELP}: the model to fit (identify, wear; default nonlinear) or "
                             "the baseline (diagnose; default linear)")
    parser.add_argument("--params", metavar="P.json",
                        help="wear only: one parameter file for every run instead of a fit per task")
    parser.add_argument("--group-by", metavar="ATTR", type=cliargs.attribute_name,
                        help="runs sharing this root attribute (e.g. a clutch's id) are one task, fitted together")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="an existing dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    parser.add_argument("--workers", type=cliargs.count("worker processes", MAX_LOCAL_WORKERS), default=workers(),
                        help="local cluster only: worker processes, one thread each (default: the usable cores)")
    parser.add_argument("--connect-timeout", type=cliargs.positive_float("a time-out in s", MAX_TIMEOUT_S),
                        default=10.0, metavar="S", help="how long to wait for --scheduler to answer")
    parser.add_argument("--starts", type=cliargs.count("a number of starting points", MAX_FIT_STARTS), default=6,
                        help="starting points of each fit")
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="seed of the fits and the wear Monte Carlo")
    parser.add_argument("--force", action="store_true", help="--out may hold files already: replace the ones the "
                                                             "batch writes (never a run file)")


def describe(conn: Connection) -> str:
    """Where the batch runs, in one line."""
    if conn.local:
        return (f"local cluster of {conn.workers} worker process(es), scheduler {conn.scheduler} "
                f"(loopback only)")
    waiting = "" if conn.workers else ": no worker connected yet, tasks wait for one"
    return f"scheduler {conn.scheduler}, {conn.workers} worker(s){waiting}"


def run(args: argparse.Namespace) -> int:
    """Plan the tasks, run them on the cluster, write the table and the trends; exit 1 if any run failed."""
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        require_distributed()
        from benchlab.batch import adapter, plan, table, trends
        from benchlab.batch.submit import run_batch
        from benchlab.batch.tasks import FAILED, Job
    if args.params is not None and args.kind != "wear":
        raise InputError("--params", f"batch {args.kind}", "--params only with `batch wear` (identify and diagnose "
                                                           "fit their own parameters)")
    if args.params is not None:
        adapter.read_params(args.params)  # bad input before any cluster starts
    out = check_output_dir(args.out, "--out", args.force)
    out.mkdir(exist_ok=True)
    tasks = plan.plan(plan.expand(args.runs), args.group_by)
    runs = sum(len(t.runs) for t in tasks)
    job = Job(args.kind, adapter.model_text(args.model or DEFAULT_MODEL[args.kind]), str(out.resolve()), args.starts,
              args.seed, None if args.params is None else str(Path(args.params).resolve()))
    with connect(args.scheduler, args.workers, args.connect_timeout) as conn:
        print(f"batch {args.kind}: {runs} run(s) in {len(tasks)} task(s) on a {describe(conn)}", flush=True)
        print(f"dashboard: {conn.dashboard or f'none (bokeh not installed: {EXTRA} installs it)'}", flush=True)
        rows = run_batch(conn.client, job, tasks, for_terminal(args.quiet))
    results = table.frame(rows)
    path = table.write(results, out)
    failed = int((results["status"] == FAILED).sum())
    why = "" if table.table_format() == "parquet" else "; Parquet where pyarrow is installed"
    print(f"table: {path} ({table.table_format()}{why}), {len(results)} row(s): {len(results) - failed} ok, "
          f"{failed} failed")
    print(f"files: {out}/{FILES[args.kind]}")
    columns = trends.series(results, args.kind)
    if columns:
        figure = trends.plot(results, columns, out / "trends.png", f"benchlab batch {args.kind}: {out.name}")
        summary = trends.trend_table(results, columns)
        write_text(out / "trends.csv", summary.to_csv(index=False))
        print(f"trends: {figure}, {out / 'trends.csv'} ({summary['axis'].iloc[0]})")
    for row in results[results["status"] == FAILED].itertuples():
        print(f"failed: {row.error if row.error.startswith(row.run) else f'{row.run}: {row.error}'}")
    return 1 if failed else 0
