"""A settable clock for simulated time: emulators and drivers take any `() -> seconds` callable."""

from __future__ import annotations


class ManualClock:
    """Callable clock that only moves when told to; `clock()` returns the current simulated time in s."""

    def __init__(self, t0: float = 0.0) -> None:
        self.t = t0

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> float:
        """Move forward by `dt` seconds and return the new time."""
        if dt < 0:
            raise ValueError("time does not go backwards")
        self.t += dt
        return self.t
