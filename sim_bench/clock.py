"""The clock the whole stack shares: simulated time (deterministic, as fast as the CPU allows) or real time.

Drivers and emulators take any `() -> seconds` callable; both clocks are such callables. The runner only
ever calls `clock()` and `clock.sleep_until(t)`: on the simulated clock that jumps to `t` at once, on the
real clock it sleeps. Times are seconds since the run started (`t0` on resume).
"""

from __future__ import annotations

import time

from sim_bench.emulators.clock import ManualClock


class SimClock(ManualClock):
    """Simulated time: moves only when told to, so a 2-hour protocol runs in seconds and is deterministic."""

    realtime = False

    def __init__(self, t0: float = 0.0) -> None:
        super().__init__(float(t0))

    def sleep_until(self, t: float) -> float:
        """Jump to `t` (never backwards) and return the new time."""
        self.t = max(self.t, float(t))
        return self.t


class RealClock:
    """Wall-clock time since construction (monotonic), offset by `t0`; `sleep_until` really sleeps."""

    realtime = True

    def __init__(self, t0: float = 0.0) -> None:
        self._origin = time.monotonic() - float(t0)

    def __call__(self) -> float:
        return time.monotonic() - self._origin

    def sleep_until(self, t: float) -> float:
        """Sleep until `t` (returns at once if it has passed) and return the time."""
        delay = t - self()
        if delay > 0:
            time.sleep(delay)
        return self()


Clock = SimClock | RealClock
