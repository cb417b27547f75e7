"""Shared fixtures: small simulated runs written as contract run files."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np
import pytest

from benchlab.model.params import paper_params, save_params
from benchlab.runfile import ALIGNED_UNITS, REQUIRED, write_run
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C answered in this process and the commands it starts, however the suite was launched: a shell without
    job control starts a background job (`cmd &`, a CI runner's) with SIGINT ignored, which every child inherits,
    and the tests of Ctrl-C would then time out or see the command run on past the interrupt.

    Under pytest-xdist, each worker keeps to its share of the cores: the suite already runs one test per core,
    and a diagnosis in a worker that may use every core forks a pool onto cores the other workers are busy on
    (≈ 17 % more CPU for the same fits). benchlab.diagnose.parallel uses the cores the process may run on."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    worker, count = os.environ.get("PYTEST_XDIST_WORKER"), os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if worker is None or count is None or not hasattr(os, "sched_setaffinity"):
        return
    cores, index = sorted(os.sched_getaffinity(0)), int(worker.removeprefix("gw"))
    share = cores[index::int(count)] or [cores[index % len(cores)]]
    os.sched_setaffinity(0, share)


#: Files of long diagnoses on runs simulated without the drivers, collected first, after the main job's first test
#: (its fixture runs the job once for the session, ≈ 70 s). xdist hands the tests out one at a time in this order to
#: whichever worker has at most two queued (`--dist loadgroup --no-loadscope-reorder` in pyproject.toml, with no
#: groups: pytest 9 ignores xdist 3.8's xdist_group), so the longest go first and the short files fill the end; and
#: at start-up only the other worker compiles the drivers' and emulators' kernels (≈ 40 s of numba on a fresh clone).
#: The main job's other tests come after the diagnoses: by then the job is written, and no worker waits on its lock
#: (measured: 144 s of waiting with the job's three tests first).
FIRST = ("test_diagnose.py", "test_diagnose_unseen.py")
JOB = "test_pipeline.py"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    job = [item for item in items if item.path.name == JOB]

    def rank(item: pytest.Item) -> int:
        if item.path.name == JOB:
            return 0 if item is job[0] else 2
        return 1 if item.path.name in FIRST else 3
    items.sort(key=rank)  # stable: the order within each part is kept


@pytest.fixture(scope="session")
def short_run():
    """A 20-minute Table 1 run on the simulated bench with the paper's nonlinear clutch."""
    return run_schedule(table1_schedule(7, duration_s=1200), ThermalPlant(), seed=7)


@pytest.fixture()
def run_file(tmp_path, short_run):
    path = tmp_path / "run.h5"
    write_run(path, short_run, short_run.attrs["dt"], protocol="table1")
    return path


@pytest.fixture()
def foreign_run(tmp_path):
    """A 30 s contract-conforming file written with h5py alone, the way another tool would (float32, 0.1 s)."""
    path, n, dt = tmp_path / "f.h5", 300, 0.1
    with h5py.File(path, "w") as f:
        f.attrs["schema"], f.attrs["status"], f.attrs["protocol"] = "benchlab-run/1", "complete", "imported"
        g = f.create_group("aligned")
        g.attrs["dt"] = dt
        for name in REQUIRED:
            values = np.arange(n) * dt if name == "time" else np.full(n, 30.0)
            if name == "friction_power":
                values = np.where(np.arange(n) < 100, 4000.0, 0.0)
            if name == "clutch_state":
                values = np.ones(n)
            g.create_dataset(name, data=values.astype(np.float32)).attrs["units"] = np.bytes_(ALIGNED_UNITS[name])
    return path


@pytest.fixture()
def params_file(tmp_path):
    """The paper's nonlinear parameters as a parameter file."""
    path = tmp_path / "p.json"
    save_params(path, paper_params("nonlinear"))
    return path


@pytest.fixture
def refused(capsys: pytest.CaptureFixture[str]) -> Callable[..., str]:
    """`refused(argv, *words)`: `benchlab ARGV` run in-process is bad input as the contract says (exit 2, one line
    on stderr holding each of `words`, no traceback, no `failed:`); returns that line."""
    from benchlab.cli import main

    def check(argv: list[str], *words: str) -> str:
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code
        err = capsys.readouterr().err.strip()
        assert code == 2, err
        assert len(err.splitlines()) == 1 and "Traceback" not in err and "failed:" not in err, err
        for word in words:
            assert word in err, err
        return err
    return check


@pytest.fixture
def opened_benches(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Every bench the session opens (the only way a set-point reaches a controller): an entry as soon as opening
    starts, then {"bench": its DriverBench, "sim": the SimBench or None}, readable after the run closed them."""
    import benchlab.runner.session as session

    opened: list[dict[str, Any]] = []
    real = session.open_bench

    def recording(*args: Any, **kwargs: Any) -> Any:
        entry: dict[str, Any] = {}
        opened.append(entry)
        bench, clock, sim, config = real(*args, **kwargs)
        entry.update(bench=bench, sim=sim)
        return bench, clock, sim, config

    monkeypatch.setattr(session, "open_bench", recording)
    return opened
