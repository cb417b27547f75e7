"""The simulated bench's clock: simulated time (deterministic, as fast as the CPU allows).

Drivers and emulators take any `() -> seconds` callable. The runner only ever calls `clock()` and
`clock.sleep_until(t)` (`benchlab.runner.clock.Clock`): here that jumps to `t` at once; the hardware bench's
`RealClock` sleeps. Times are seconds since the run started (`t0` on resume).
"""

from __future__ import annotations

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
