"""The simulated bench's clock: simulated time (deterministic, as fast as the CPU allows).

Drivers and emulators take any `() -> seconds` callable. The runner only ever calls `clock()` and
`clock.sleep_until(t)` (`benchlab.runner.clock.Clock`): here that jumps to `t` at once; the hardware bench's
`RealClock` sleeps. Times are seconds since the run started (`t0` on resume).
"""

from __future__ import annotations

import time

from sim_bench.emulators.clock import ManualClock

#: Paced, how far behind the wall clock simulated time may fall before pacing starts again from now (s).
MAX_LAG_S = 0.5


class SimClock(ManualClock):
    """Simulated time: moves only when told to, so a 2-hour protocol runs in seconds and is deterministic.

    With `pace` (a factor), `sleep_until` also waits on the wall clock so simulated time runs at `pace` x real time
    (`benchlab run --realtime`): the live view, Ctrl-C and the interlocks can be rehearsed at the speed a hardware
    bench has. The run's data are the same either way; only the wall-clock time it takes changes.
    """

    realtime = False

    def __init__(self, t0: float = 0.0, pace: float | None = None) -> None:
        super().__init__(float(t0))
        if pace is not None and not pace > 0:
            raise ValueError(f"pace: a factor > 0, got {pace!r}")
        self.pace = pace
        self._origin: tuple[float, float] | None = None  # wall and simulated time pacing counts from

    def sleep_until(self, t: float) -> float:
        """Jump to `t` (never backwards) and return the new time; paced, first wait until the wall clock is there.

        Pacing counts from the first wait; time lost beyond MAX_LAG_S (the bench starting up, a loaded machine) is
        not made up in a burst, as a hardware bench would not make it up either."""
        if self.pace is not None:
            now = time.monotonic()
            if self._origin is None:
                self._origin = (now, self.t)
            wall0, sim0 = self._origin
            delay = wall0 + (t - sim0) / self.pace - now
            if delay > 0:
                time.sleep(delay)
            elif delay < -MAX_LAG_S:
                self._origin = (now, float(t))
        self.t = max(self.t, float(t))
        return self.t
