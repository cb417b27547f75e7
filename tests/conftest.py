"""Shared fixtures: small simulated runs written as contract run files."""

from __future__ import annotations

import pytest

from benchlab.runfile import write_run
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule


@pytest.fixture(scope="session")
def short_run():
    """A 20-minute Table 1 run on the simulated bench with the paper's nonlinear clutch."""
    return run_schedule(table1_schedule(7, duration_s=1200), ThermalPlant(), seed=7)


@pytest.fixture()
def run_file(tmp_path, short_run):
    path = tmp_path / "run.h5"
    write_run(path, short_run, short_run.attrs["dt"], protocol="table1")
    return path
