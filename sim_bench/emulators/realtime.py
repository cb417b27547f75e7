"""Optional real-time mode: poll emulators (and drivers) from a background thread at a fixed period."""

from __future__ import annotations

import threading
from collections.abc import Callable
from types import TracebackType


class RealtimeLoop:
    """Calls every `poll` callable each `period_s` of wall time until stopped; use as a context manager."""

    def __init__(self, *polls: Callable[[], object], period_s: float = 0.002) -> None:
        self.polls, self.period_s = polls, period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-bench-realtime", daemon=True)

    def start(self) -> "RealtimeLoop":
        """Start the thread."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and wait for it."""
        self._stop.set()
        self._thread.join()

    def __enter__(self) -> "RealtimeLoop":
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            for poll in self.polls:
                poll()
