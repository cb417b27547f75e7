"""`benchlab batch` on real dask clusters bound to 127.0.0.1: tables, per-run files, trends, failures as rows,
bad usage as one line and exit 2; diagnose's executor inside a dask worker process and thread."""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import socket
import sys
import time

import h5py
import numpy as np
import pandas as pd
import pytest

distributed = pytest.importorskip("distributed")
import cloudpickle  # noqa: E402 - comes with distributed

from benchlab.batch import plan, table, trends  # noqa: E402
from benchlab.batch.cluster import LOOPBACK, connect  # noqa: E402
from benchlab.cli import main  # noqa: E402
from benchlab.diagnose import parallel  # noqa: E402
from benchlab.diagnose.parallel import map_indices  # noqa: E402
from benchlab.interrupts import terminate_as_interrupt  # noqa: E402
from benchlab.model.catalog import BUILTIN  # noqa: E402
from benchlab.model.params import load_params, paper_params, save_params  # noqa: E402
from benchlab.runfile import load_run, write_run  # noqa: E402
from benchlab.wear.analysis import analyse_wear  # noqa: E402
from protocols.table1 import table1_schedule  # noqa: E402
from sim_bench.plant import ThermalPlant  # noqa: E402
from sim_bench.virtual_run import run_schedule  # noqa: E402

# The probes below run in spawned worker processes, which cannot import this test module: ship them by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

CLUTCHES = ("A", "A", "B")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Three 20-minute Table 1 runs at 0.1 s (clutch A, A, B, a month apart) and a file that is not HDF5."""
    folder = tmp_path_factory.mktemp("runs")
    for i, clutch in enumerate(CLUTCHES):
        run = run_schedule(table1_schedule(i, duration_s=1200), ThermalPlant(), seed=i, dt=0.1)
        path = folder / f"run{i + 1}.h5"
        write_run(path, run, run.attrs["dt"], protocol="table1")
        with h5py.File(path, "a") as f:
            f.attrs["clutch"] = clutch
            f.attrs["created_utc"] = f"2026-0{i + 1}-01T10:00:00+00:00"
    (folder / "run10.h5").write_text("not an HDF5 file")
    return folder


@pytest.fixture(scope="module")
def scheduler():
    """A scheduler on 127.0.0.1 with one worker of two threads in this process (no processes to start)."""
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp://",
                                  host=LOOPBACK, dashboard_address=f"{LOOPBACK}:0") as cluster:
        # not dashboard_address=None: the scheduler then takes dask's fixed port 8787, taken under a parallel run
        yield cluster.scheduler_address


def _batch(*argv: str) -> int:
    return main(["batch", *argv, "--quiet"])


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ----------------------------------------------------------------------------- diagnose's executor in dask

def _pid_and_square(i: int) -> tuple[int, int]:
    return os.getpid(), i * i


def _busy_square(i: int) -> tuple[int, int]:
    """A task that keeps its worker busy for 50 ms."""
    until = time.monotonic() + 0.05
    while time.monotonic() < until:
        pass
    return os.getpid(), i * i


def _map_in_worker() -> dict:
    """What map_indices does where it runs: its results and the processes they came from."""
    results = map_indices(_pid_and_square, 4)
    return {"pid": os.getpid(), "daemon": multiprocessing.current_process().daemon,
            "pids": {pid for pid, _ in results}, "squares": [sq for _, sq in results],
            "malloc_trim": os.environ.get("MALLOC_TRIM_THRESHOLD_")}


def test_map_indices_in_a_dask_worker_process_runs_serially_and_the_cluster_is_loopback_only(monkeypatch):
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with connect(None, 1, 10.0) as conn:
        addresses = list(conn.client.scheduler_info()["workers"])
        assert conn.scheduler.startswith(f"tcp://{LOOPBACK}:")
        assert addresses and all(a.startswith(f"tcp://{LOOPBACK}:") for a in addresses)
        seen = conn.client.submit(_map_in_worker, pure=False).result(timeout=120)
    assert seen["daemon"], "a dask worker process is daemonic: the case that broke the fork pool"
    assert seen["squares"] == [0, 1, 4, 9]
    assert seen["pids"] == {seen["pid"]}
    assert seen["malloc_trim"] is None  # dask's 65536 would make every fit's large arrays mmap'ed afresh


def test_map_indices_workers_end_quietly_under_the_commands_sigterm_answer(monkeypatch, capfd):
    """Every command answers SIGTERM by raising in the main thread (benchlab.interrupts); the fork pool's workers must
    not inherit that answer, or each worker the pool ends at its close prints a Terminated traceback (the main job's
    diagnose step did, 8 of them)."""
    monkeypatch.setattr(parallel, "workers", lambda: 2)  # fork even on one core
    with terminate_as_interrupt():
        for _ in range(10):  # three tasks on two workers: one waits for work when the pool ends them
            results = map_indices(_busy_square, 3)
            assert [sq for _, sq in results] == [0, 1, 4]
            assert {pid for pid, _ in results} != {os.getpid()}  # forked
    err = capfd.readouterr().err
    assert "Terminated" not in err and "Traceback" not in err, err


def test_a_long_map_goes_out_in_chunks_and_comes_back_in_order(monkeypatch):
    """Issue 47: a map of many short tasks (diagnose's score test: 336 candidates) goes to the workers in chunks,
    not one task per round trip; its results come back in order, one progress call each."""
    monkeypatch.setattr(parallel, "workers", lambda: 2)
    sizes = []
    real_chunk_size = parallel.chunk_size
    monkeypatch.setattr(parallel, "chunk_size", lambda count, n: sizes.append(real_chunk_size(count, n)) or sizes[-1])
    progress = []
    results = map_indices(lambda i: (os.getpid(), i * i), 336, lambda: progress.append(1))
    assert [sq for _, sq in results] == [i * i for i in range(336)] and len(progress) == 336
    assert {pid for pid, _ in results} != {os.getpid()}  # forked
    assert sizes[-1] > 1 and real_chunk_size(3, 2) == 1  # a long map in chunks, a short one task by task


def test_map_indices_in_a_dask_worker_thread_runs_serially_where_it_would_fork_elsewhere(scheduler, monkeypatch):
    monkeypatch.setattr(parallel, "workers", lambda: 2)  # two cores to fork onto, however many this process has
    with distributed.Client(scheduler) as client:
        seen = client.submit(_map_in_worker, pure=False).result(timeout=60)
    assert not seen["daemon"] and seen["pid"] == os.getpid()  # a thread of this very process
    assert seen["squares"] == [0, 1, 4, 9] and seen["pids"] == {os.getpid()}
    # outside a worker the same call forks: the serial path above was chosen, not the default
    assert _map_in_worker()["pids"] != {os.getpid()}


# ----------------------------------------------------------------------------- batches

def test_identify_batch_table_files_trends_and_a_bad_file_as_a_row(runs, scheduler, tmp_path, capsys):
    out = tmp_path / "out"
    code = _batch("identify", str(runs / "*.h5"), "--out", str(out), "--scheduler", scheduler, "--starts", "1")
    printed = capsys.readouterr().out
    assert code == 1  # the table is complete, one run failed
    path = out / f"batch.{table.table_format()}"
    assert f"table: {path}" in printed and "4 row(s): 3 ok, 1 failed" in printed
    result = table.read(path)
    assert list(result["run"]) == [str(runs / f"run{i}.h5") for i in (1, 2, 3, 10)]  # run10 after run3
    assert list(result["status"]) == ["ok", "ok", "ok", "failed"]
    bad = result.iloc[3]
    assert "run10.h5" in bad["error"] and "HDF5" in bad["error"] and math.isnan(bad["R0"])
    for row in result.iloc[:3].itertuples():
        params = load_params(row.params_file)
        assert params["R0"] == pytest.approx(row.R0, rel=1e-12) and params["C_P"] == pytest.approx(row.C_P, rel=1e-12)
        assert 0 < row.R0_se < 0.1 * row.R0 and 0 < row.C_P_se < 0.1 * row.C_P
        assert row.rmse_K < 0.2  # simulated sensors: noise of a few hundredths of a kelvin
    assert (out / "trends.png").stat().st_size > 10_000
    summary = pd.read_csv(out / "trends.csv").set_index("column")
    assert summary.loc["R0", "points"] == 3 and summary.loc["R0", "axis"].startswith("days since 2026-01-01")
    assert np.isfinite(summary.loc["R0", "slope_se_per_day"])


def test_group_by_fits_a_clutch_runs_together_with_a_model_file_given_by_relative_path(
        runs, scheduler, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    paths = [str(runs / f"run{i}.h5") for i in (1, 2, 3)]
    model = tmp_path / "models" / "my-clutch.toml"  # a user's own file, named relative to the client's directory
    model.parent.mkdir()
    model.write_text(BUILTIN["linear"].read_text().replace('name = "clutch-linear"', 'name = "my-clutch"'))
    monkeypatch.chdir(tmp_path)
    code = _batch("identify", *paths, "--out", str(out), "--scheduler", scheduler, "--model", "models/my-clutch.toml",
                  "--starts", "1", "--group-by", "clutch")
    assert code == 0, capsys.readouterr()
    result = table.read(out / f"batch.{table.table_format()}")
    assert list(result["task"]) == ["clutch-A", "clutch-B"] and list(result["group"]) == ["A", "B"]
    assert list(result["runs"]) == [2, 1] and result["run"].iloc[0] == ";".join(paths[:2])
    fitted = json.loads((out / "clutch-A.params.json").read_text())
    assert fitted["model"] == "my-clutch" and len(fitted["fit"]["fitting"]) == 2  # both runs in one fit
    assert fitted["network"]["name"] == "my-clutch"  # the parameter file carries the model it was fitted for


def test_wear_batch_on_the_default_local_cluster_matches_wear_of_each_run(runs, tmp_path, capsys):
    out, params_file = tmp_path / "out", tmp_path / "p.json"
    save_params(params_file, paper_params("nonlinear"))
    code = _batch("wear", str(runs / "run[12].h5"), "--out", str(out), "--params", str(params_file),
                  "--workers", "1")
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert f"scheduler tcp://{LOOPBACK}:" in printed and "loopback only" in printed and "dashboard: " in printed
    result = table.read(out / f"batch.{table.table_format()}")
    for i, row in enumerate(result.itertuples(), start=1):
        direct = analyse_wear(load_run(runs / f"run{i}.h5"), paper_params("nonlinear"))
        assert row.friction_energy_J == pytest.approx(direct.friction_energy_j, rel=1e-9)
        assert row.engagements == len(direct.engagements) > 0
        saved = json.loads((out / f"run{i}.wear.json").read_text())
        assert saved["friction_energy_J"] == pytest.approx(direct.friction_energy_j, rel=1e-9)


def test_diagnose_batch_in_a_worker_finds_the_convection_the_linear_model_lacks(runs, scheduler, tmp_path, capsys):
    out = tmp_path / "out"
    code = _batch("diagnose", str(runs / "run3.h5"), "--out", str(out), "--scheduler", scheduler)
    assert code == 0, capsys.readouterr()
    row = table.read(out / f"batch.{table.table_format()}").iloc[0]
    assert row["findings"] >= 1 and "convection/engine_speed" in row["finding_summaries"]
    assert row["best_rmse_K"] < row["baseline_rmse_K"]
    doc = json.loads((out / "run3.diagnose.json").read_text())
    assert doc["baseline"]["model"] == "linear" and doc["findings"][0]["mechanism"] == "convection"


def test_a_task_dask_could_not_run_is_a_row(runs, scheduler, tmp_path, monkeypatch, capsys):
    import benchlab.batch.submit as submit
    real = submit.run_task

    def dies_on_run2(job, task):
        if task.name == "run2":
            raise MemoryError("worker ran out of memory")
        return real(job, task)

    monkeypatch.setattr(submit, "run_task", dies_on_run2)
    out = tmp_path / "out"
    code = _batch("wear", str(runs / "run[12].h5"), "--out", str(out), "--scheduler", scheduler,
                  "--params", str(_paper_file(tmp_path)))
    assert code == 1
    result = table.read(out / f"batch.{table.table_format()}")
    assert list(result["status"]) == ["ok", "failed"]
    assert result["error"].iloc[1] == "dask: MemoryError: worker ran out of memory"
    assert f"failed: {runs / 'run2.h5'}: dask: MemoryError" in capsys.readouterr().out


def _paper_file(folder) -> str:
    path = folder / "paper.json"
    save_params(path, paper_params("nonlinear"))
    return str(path)


# ----------------------------------------------------------------------------- bad usage: one line, exit 2

def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def test_bad_usage_is_one_line_and_exit_2(runs, tmp_path, capsys):
    a_file = tmp_path / "taken"
    a_file.write_text("")
    cases = [
        (["identify", str(tmp_path / "nothing" / "*.h5"), "--out", str(tmp_path / "o")], "*.h5: RUN_GLOB"),
        (["identify", str(runs / "run1.h5"), "--out", str(a_file)], "--out: a directory"),
        (["identify", str(runs / "run1.h5"), "--out", str(tmp_path / "o"), "--params", _paper_file(tmp_path)],
         "--params only with `batch wear`"),
        (["wear", str(runs / "run1.h5"), "--out", str(tmp_path / "o"), "--params", str(tmp_path / "none.json")],
         "none.json: file: an existing parameter file"),
        (["identify", str(runs / "run1.h5"), "--out", str(tmp_path / "o"), "--model", "cubic"],
         "--model: cubic: a model file (.toml) or one of linear, nonlinear"),
        (["identify", str(runs / "run1.h5"), "--out", str(tmp_path / "o"), "--scheduler",
          f"tcp://{LOOPBACK}:{_free_port()}", "--connect-timeout", "2"], "--scheduler: a dask scheduler that answers"),
    ]
    for argv, expected in cases:
        assert _batch(*argv) == 2, argv
        assert expected in _one_line(capsys.readouterr().err), argv


def test_without_dask_the_command_names_the_extra(runs, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed now raises ImportError
    assert _batch("identify", str(runs / "run1.h5"), "--out", str(tmp_path / "o")) == 2
    line = _one_line(capsys.readouterr().err)
    assert "dask.distributed" in line and "pip install -e '.[cluster]'" in line


# ----------------------------------------------------------------------------- planning, trends, table

def test_plan_orders_numbers_as_numbers_names_uniquely_and_groups(runs, tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for folder in ("a", "b"):
        (tmp_path / folder / "run.h5").write_text("")
    assert plan.run_names([str(tmp_path / "a" / "run.h5"), str(tmp_path / "b" / "run.h5")]) == ["a__run", "b__run"]
    paths = plan.expand([str(runs / "*.h5"), str(runs / "run1.h5")])
    assert [os.path.basename(p) for p in paths] == ["run1.h5", "run2.h5", "run3.h5", "run10.h5"]
    tasks = plan.plan(paths, "clutch")  # run10 cannot be read: a task of its own
    assert [(t.name, [r.index for r in t.runs]) for t in tasks] == [("clutch-A", [0, 1]), ("clutch-B", [2]),
                                                                    ("run10", [3])]


def test_trend_slope_and_its_standard_error_recover_a_known_drift():
    rng = np.random.default_rng(1)
    index = np.arange(40.0)
    se = np.full(40, 0.002)
    r0 = 0.15 + 0.001 * index + rng.normal(0.0, 0.002, 40)
    result = pd.DataFrame({"index": index.astype(int), "status": "ok", "R0": r0, "R0_se": se})
    row = trends.trend_table(result, ["R0"]).iloc[0]
    expected_se = 0.002 / np.sqrt(np.sum((index - index.mean()) ** 2))
    assert row["slope_per_run"] == pytest.approx(0.001, abs=4 * expected_se)
    assert row["slope_se_per_run"] == pytest.approx(expected_se, rel=0.35)
    scattered = result.assign(R0_se=se / 10)  # standard errors ten times too small: the scatter decides
    assert trends.trend_table(scattered, ["R0"]).iloc[0]["slope_se_per_run"] == pytest.approx(expected_se, rel=0.35)


def test_trend_flags_identical_runs_at_its_stated_rate_when_they_scatter_beyond_their_standard_errors():
    # Ten runs of one unchanged clutch whose values scatter twice as much as their standard errors say (the
    # start temperatures and sensor draws one fit's SE does not see): a test on the SEs alone cries ageing.
    rng = np.random.default_rng(7)
    x, draws = np.arange(10.0), 2000
    se = np.full(10, 0.002) * rng.uniform(0.7, 1.3, 10)
    p = np.array([trends.line_fit(x, 0.15 + rng.normal(0.0, 2 * se), se).p_value for _ in range(draws)])
    rate = np.mean(p < trends.FALSE_ALARM_RATE)
    assert rate <= trends.FALSE_ALARM_RATE + 3 * np.sqrt(trends.FALSE_ALARM_RATE / draws)
    naive = np.mean([abs(trends.line_fit(x, 0.15 + rng.normal(0.0, 2 * se), se).slope)
                     / np.sqrt(1 / np.sum((x - np.average(x, weights=se ** -2)) ** 2 / se ** 2)) > 2.576
                     for _ in range(500)])
    assert naive > 10 * trends.FALSE_ALARM_RATE  # what the standard errors alone would have flagged


def test_trend_flags_a_drifting_r0_and_nothing_else_on_a_run_index_axis_for_runs_minutes_apart():
    rng = np.random.default_rng(3)
    n = 12
    created = [f"2026-03-01T10:{2 * i:02d}:00+00:00" for i in range(n)]  # runs minutes apart
    rows = {"index": np.arange(n), "status": "ok", "created": created}
    for name, value in (("R0", 0.15), ("C_P", 1800.0), ("a2", 0.45)):
        drift = 1 + 0.03 * np.arange(n) if name == "R0" else np.ones(n)
        rows[name] = value * drift * (1 + rng.normal(0.0, 0.006, n))
        rows[name + "_se"] = np.full(n, value * 0.003)
    summary = trends.trend_table(pd.DataFrame(rows), ["R0", "C_P", "a2"]).set_index("column")
    assert summary["axis"].iloc[0] == "run index" and "slope_per_run" in summary
    assert list(summary.index[summary["drifting"]]) == ["R0"]
    assert (summary["false_alarm_rate"] == trends.FALSE_ALARM_RATE).all()


@pytest.mark.parametrize("kind", ["csv", "parquet"])
def test_table_round_trip_keeps_counts_integer_and_failed_rows(kind, tmp_path, monkeypatch):
    if kind == "parquet":
        pytest.importorskip("pyarrow")
    monkeypatch.setattr(table, "table_format", lambda: kind)
    rows = [{"index": 1, "run": "b.h5", "status": "failed", "error": "b.h5: file: bad"},
            {"index": 0, "run": "a.h5", "status": "ok", "error": "", "runs": 1, "R0": 0.15, "R0_se": 0.001}]
    path = table.write(table.frame(rows), tmp_path)
    assert path.suffix == f".{kind}"
    back = table.read(path)
    assert list(back["run"]) == ["a.h5", "b.h5"] and back["runs"].iloc[0] == 1 and math.isnan(back["R0"].iloc[1])
