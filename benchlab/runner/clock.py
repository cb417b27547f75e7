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
    """Wall-clock time since construction (monotonic), offset by `t0`; `sleep_until` really sleeps. `speed` > 1
    runs it faster than the wall clock: only for rehearsals whose every device is emulated on this clock."""

    realtime = True

    def __init__(self, t0: float = 0.0, speed: float = 1.0) -> None:
        self._start, self._t0, self.speed = time.monotonic(), float(t0), float(speed)

    def __call__(self) -> float:
        return self._t0 + (time.monotonic() - self._start) * self.speed

    def sleep_until(self, t: float) -> float:
        """Sleep until `t` (returns at once if it has passed) and return the time."""
        delay = (t - self()) / self.speed
        if delay > 0:
            time.sleep(delay)
        return self()
