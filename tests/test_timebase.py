"""A device clock mapped onto the run clock (drivers/timebase.py): within the drift allowance it is followed; beyond
it, or after a jump, it is mapped anew and counted, never left seconds off (issue 29)."""

from __future__ import annotations

import pytest

from drivers.timebase import REMAP_S, ClockMap


def _follow(rate: float, seconds: float = 2000.0, delay_s: float = 0.01, jump_at: float = -1.0,
            jump_s: float = 0.0) -> tuple[ClockMap, float]:
    """A device stamping every 0.1 s with its clock running at `rate` (jumping by `jump_s` at `jump_at`), each stamp
    received `delay_s` later: the map, and its worst error (mapped minus true measuring time, s)."""
    clock, worst, t = ClockMap(), 0.0, 0.0
    while t < seconds:
        device = t * rate + (jump_s if jump_at >= 0 and t >= jump_at else 0.0)
        mapped = clock.observe(device, t + delay_s)
        worst = max(worst, abs(mapped - t))
        t += 0.1
    return clock, worst


def test_a_clock_within_its_allowance_is_followed_without_a_remap():
    clock, worst = _follow(1.0 - 50e-6)
    assert clock.remaps == 0 and worst <= 0.02


@pytest.mark.parametrize("rate", [1.0 - 5e-3, 1.0 - 1e-3])
def test_a_slow_clock_beyond_its_allowance_is_mapped_anew_never_seconds_off(rate):
    clock, worst = _follow(rate)
    assert clock.remaps >= 1 and worst <= REMAP_S + 0.02


@pytest.mark.parametrize("jump_s", [5.0, -5.0])
def test_a_jumping_clock_is_mapped_anew_and_counted(jump_s):
    clock, worst = _follow(1.0, seconds=200.0, jump_at=100.0, jump_s=jump_s)
    assert clock.remaps == 1 and worst <= REMAP_S + 0.02
