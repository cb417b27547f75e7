"""Protocol runner: executes a schedule on a bench (hardware or simulated) with interlocks, into a run file."""

from benchlab.runner.devices import BenchConfig, BenchStatus, DriverBench, bench_layout
from benchlab.runner.engine import Runner, RunSummary, Stopped
from benchlab.runner.interlocks import InterlockSet

__all__ = ["BenchConfig", "BenchStatus", "DriverBench", "InterlockSet", "RunSummary", "Runner", "Stopped", "bench_layout"]
