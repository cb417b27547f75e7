"""A device's own clock mapped onto the run clock: readings keep the time they were measured.

A device stamps what it measures on its clock (a CAN interface's receive time stamps, the flywheel node's
millisecond counter); the host receives it a little later, on the run clock. The offset between the two
clocks is estimated as the smallest (receive time − device stamp) seen, since transport delays only add:
the frame that arrived fastest shows the offset best. The estimate may rise by at most `drift_ppm` of the
time elapsed (so a slowly drifting device clock is followed) and falls at once to any smaller difference.
"""

from __future__ import annotations

import math

import numpy as np


class ClockMap:
    """Device time → run time, from pairs (device stamp, run-clock receive time)."""

    def __init__(self, drift_ppm: float = 100.0) -> None:
        self.drift = drift_ppm * 1e-6
        self.offset = math.nan  # run time − device time
        self._last_receive = math.nan

    def observe(self, device_t: float, received_t: float) -> float:
        """Update the offset with one frame and return the frame's run time (never later than its receipt)."""
        offset = received_t - device_t
        if math.isnan(self.offset):
            self.offset = offset
        else:
            grown = self.offset + self.drift * max(0.0, received_t - self._last_receive)
            self.offset = min(grown, offset)
        self._last_receive = received_t
        return device_t + self.offset

    def observe_together(self, device_t: np.ndarray, received_t: float) -> None:
        """`observe` of frames received together at `received_t`, in order (the offset is the same as one by one)."""
        self.observe(float(device_t[0]), received_t)
        self.offset = min(self.offset, float(np.min(received_t - device_t)))

    def to_run(self, device_t: "float | np.ndarray") -> "float | np.ndarray":
        """Run time of a device stamp (or stamps) with the current offset (NaN before the first frame)."""
        return device_t + self.offset

    def to_device(self, run_t: float) -> float:
        """Device time of a run time (to stamp frames the host sends, in the device's time base)."""
        return run_t - self.offset if not math.isnan(self.offset) else run_t
