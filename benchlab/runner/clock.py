"""The runner's clock: what it needs of one (`Clock`) and the hardware bench's (`RealClock`).

The simulated bench brings its own (`sim_bench.clock.SimClock`, time that jumps); both are `() -> seconds`
callables with `sleep_until(t)`. Times are seconds since the run started (`t0` on resume).
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """Seconds since the run started, and a way to wait until a time (the loop's only two needs)."""

    def __call__(self) -> float: ...
    def sleep_until(self, t: float) -> float: ...


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
