"""Protocol runner: executes a schedule on a bench (hardware or simulated) with interlocks, into a run file."""

from benchlab.runner.devices import BenchConfig, BenchStatus, DriverBench, bench_layout
from benchlab.runner.engine import Interlocks, Runner, RunSummary, Stopped

__all__ = ["BenchConfig", "BenchStatus", "DriverBench", "Interlocks", "RunSummary", "Runner", "Stopped", "bench_layout"]
