"""A device's own clock mapped onto the run clock: readings keep the time they were measured.

A device stamps what it measures on its clock (a CAN interface's receive time stamps, the flywheel node's
millisecond counter); the host receives it a little later, on the run clock. The offset between the two
clocks is estimated as the smallest (receive time − device stamp) seen, since transport delays only add:
the frame that arrived fastest shows the offset best. The estimate may rise by at most `drift_ppm` of the
time elapsed (so a slowly drifting device clock is followed) and falls at once to any smaller difference.

A device clock that drifts beyond that allowance (or jumps) would be shifted by seconds: when the newest frame
would sit more than `REMAP_S` before its receipt, or the offset falls by more than that at once, the map starts
again from that frame and counts a re-map (`ClockMap.remaps`), which the driver reports as an event.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_OFFSET, _LAST_RECEIVE, _DRIFT, _REMAPS = range(4)  # ClockMap.state
REMAP_S = 0.5  # s: a device clock off by more than this is mapped anew (never shifted by seconds unnoticed)


class ClockMap:
    """Device time → run time, from pairs (device stamp, run-clock receive time).

    Its state is one small array (`state`: offset, last receive time, drift) so compiled code can update it with
    `observe_into`, the one implementation of the rule.
    """

    def __init__(self, drift_ppm: float = 100.0) -> None:
        self.state = np.array([np.nan, np.nan, drift_ppm * 1e-6, 0.0])

    @property
    def drift(self) -> float:
        """How fast the offset may rise: s per s of run time."""
        return float(self.state[_DRIFT])

    @property
    def remaps(self) -> int:
        """How often the map started again because the device clock drifted beyond the allowance or jumped."""
        return int(self.state[_REMAPS])

    @property
    def offset(self) -> float:
        """Run time − device time (NaN before the first frame)."""
        return float(self.state[_OFFSET])

    def observe(self, device_t: float, received_t: float) -> float:
        """Update the offset with one frame and return the frame's run time (never later than its receipt)."""
        return device_t + observe_into(self.state, device_t, device_t, received_t)

    def to_run(self, device_t: "float | np.ndarray") -> "float | np.ndarray":
        """Run time of a device stamp (or stamps) with the current offset (NaN before the first frame)."""
        return device_t + self.offset

    def to_device(self, run_t: float) -> float:
        """Device time of a run time (to stamp frames the host sends, in the device's time base)."""
        offset = self.offset
        return run_t - offset if not math.isnan(offset) else run_t


@njit(cache=True, nogil=True)
def observe_into(state: np.ndarray, first_t: float, latest_t: float,
                 received_t: float) -> float:  # pragma: no cover - compiled
    """Update a ClockMap's `state` with frames received together at `received_t`, the first stamped `first_t`, the
    latest `latest_t` (one frame: both the same): the offset may grow by the drift since the last receipt, and
    falls to any smaller receive − stamp difference; beyond REMAP_S either way it is the newest frame's and a
    re-map is counted. Returns the new offset."""
    offset = received_t - first_t
    if not np.isnan(state[_OFFSET]):
        offset = min(state[_OFFSET] + state[_DRIFT] * max(0.0, received_t - state[_LAST_RECEIVE]), offset)
    offset = min(offset, received_t - latest_t)
    if not np.isnan(state[_OFFSET]) and (received_t - latest_t - offset > REMAP_S
                                         or state[_OFFSET] - offset > REMAP_S):
        offset = received_t - latest_t
        state[_REMAPS] += 1.0
    state[_OFFSET], state[_LAST_RECEIVE] = offset, received_t
    return offset


def prime() -> None:
    """Compile (or load from numba's cache) `observe_into` for the one signature the drivers call it with, on a
    scratch state: a control loop must never stall on a first-call compile."""
    observe_into(ClockMap().state, 0.0, 0.0, 0.0)
