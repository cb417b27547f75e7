"""The interlocks: small objects, each with a condition, a hysteresis and an action (bluesky's suspenders).

Every tick the runner asks the `InterlockSet` which interlocks have newly tripped. A tripped interlock
stays active until its own clear condition holds (an over-temperature some kelvin below its limit, a
stale channel fresh again, a controller back, the clutch no longer slipping); its action, from the
limits, is "hold" (safe state until every active interlock has cleared) or "abort".

A reading older than its maximum age is an unknown reading: a silent instrument, an unplugged port, a
silent controller or a silent radio trips the `stale_<channel>` interlock of each channel it feeds, so an
interlock never watches a value that has stopped changing.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field

from benchlab.runner.devices import BenchStatus
from protocols.limits import ALARM_RISE_K, ALARM_WINDOW_S, DEFAULT_MAX_AGE_S, BenchLimits


@dataclass
class Engagements:
    """Slip intervals and friction energy, from the bench's frame-by-frame energy integral (not tick × power).

    Only while the clutch actuator's frames are fresh (within `max_age_s`): a silent actuator's held torque and
    state are no engagement (its energy was never dissipated as far as anyone knows; its stale interlock trips).
    """

    max_age_s: float = DEFAULT_MAX_AGE_S["clutch_torque"]
    slip_start: float | None = None
    slip_energy: float = 0.0
    total_energy: float = 0.0
    count: int = 0
    _last_energy: float | None = None

    def update(self, st: BenchStatus, now: float, events: list[tuple[str, str]]) -> None:
        """Engagement starts/ends at this tick, as events."""
        fresh = now - st.seen.get("clutch_torque", -math.inf) <= self.max_age_s
        energy = st.friction_energy_j - (self._last_energy if self._last_energy is not None else st.friction_energy_j)
        energy = energy if fresh else 0.0
        self._last_energy = st.friction_energy_j
        self.total_energy += energy
        if self.slip_start is not None:
            self.slip_energy += energy
        if st.slipping and fresh:
            if self.slip_start is None:
                self.slip_start, self.slip_energy = now, energy
                self.count += 1
                events.append(("engagement_start", ""))
        elif self.slip_start is not None:
            events.append(("engagement_end", f"slip {now - self.slip_start:.2f} s, {self.slip_energy / 1e3:.1f} kJ"))
            self.slip_start = None


@dataclass(frozen=True)
class OverTemperature:
    """A temperature above its limit; clears `margin_k` below it."""

    name: str
    channel: str
    limit_c: float
    margin_k: float

    def tripped(self, st: BenchStatus, eng: Engagements, now: float) -> str | None:
        value = getattr(st, self.channel)
        return f"{self.channel} {value:.1f} > {self.limit_c:g} degC" if value > self.limit_c else None

    def cleared(self, st: BenchStatus, eng: Engagements, now: float) -> bool:
        return not getattr(st, self.channel) > self.limit_c - self.margin_k


@dataclass(frozen=True)
class StaleReading:
    """No valid reading of `channel` for longer than `max_age_s` (counted from when the set was armed)."""

    name: str
    channel: str
    max_age_s: float
    armed_at: float

    def age(self, st: BenchStatus, now: float) -> float:
        return now - max(st.seen.get(self.channel, -math.inf), self.armed_at)

    def tripped(self, st: BenchStatus, eng: Engagements, now: float) -> str | None:
        age = self.age(st, now)
        return f"no valid {self.channel} for {age:.1f} s > {self.max_age_s:g} s" if age > self.max_age_s else None

    def cleared(self, st: BenchStatus, eng: Engagements, now: float) -> bool:
        return self.age(st, now) <= min(1.0, self.max_age_s)  # fresh again, not merely younger than the limit


@dataclass(frozen=True)
class ControllerLost:
    """A controller's heartbeat lost or a fault code reported (the CAN driver's watchdog)."""

    name: str = "controller_lost"

    def tripped(self, st: BenchStatus, eng: Engagements, now: float) -> str | None:
        bad = st.controllers_bad
        return ", ".join(f"{c} {why}" for c, why in sorted(bad.items())) if bad else None

    def cleared(self, st: BenchStatus, eng: Engagements, now: float) -> bool:
        return not st.controllers_bad


@dataclass(frozen=True)
class EngagementLimit:
    """One engagement slipping too long (`slip_time`, s) or dissipating too much (`slip_energy`, J).

    Clears when the clutch no longer slips.
    """

    name: str
    limit: float

    def measure(self, eng: Engagements, now: float) -> float | None:
        """This engagement's slip time or energy so far; None between engagements."""
        if eng.slip_start is None:
            return None
        return eng.slip_energy if self.name == "slip_energy" else now - eng.slip_start

    def tripped(self, st: BenchStatus, eng: Engagements, now: float) -> str | None:
        value = self.measure(eng, now)
        if value is None or value <= self.limit:
            return None
        if self.name == "slip_energy":
            return f"{value / 1e3:.1f} kJ > {self.limit / 1e3:g} kJ"
        return f"slipping {value:.1f} s > {self.limit:g} s"

    def cleared(self, st: BenchStatus, eng: Engagements, now: float) -> bool:
        return not st.slipping


Interlock = OverTemperature | StaleReading | ControllerLost | EngagementLimit


@dataclass(frozen=True)
class Trip:
    """One interlock that has just tripped: its name, what it saw and what it does."""

    name: str
    detail: str
    action: str


@dataclass
class InterlockSet:
    """The interlocks of a run (built from the limits), which of them are active, and their actions."""

    limits: BenchLimits
    armed_at: float
    interlocks: tuple[Interlock, ...] = ()
    active: dict[str, Interlock] = field(default_factory=dict)
    _tripped_at: dict[str, float] = field(default_factory=dict)  # active interlock -> when it tripped
    _recent: dict[str, collections.deque] = field(default_factory=dict)  # over-temperature -> (t, reading) recent

    def __post_init__(self) -> None:
        lim = self.limits
        items: list[Interlock] = [
            OverTemperature("flywheel_over_temperature", "T_flywheel", lim.max_flywheel_c, lim.clear_margin_k),
            OverTemperature("air_over_temperature", "T_air", lim.max_air_c, lim.clear_margin_k)]
        if lim.heartbeat:
            items.append(ControllerLost())
        items += [StaleReading(f"stale_{channel}", channel, lim.max_age_s[channel], self.armed_at)
                  for channel in DEFAULT_MAX_AGE_S]
        items += [EngagementLimit("slip_time", lim.max_slip_time_s), EngagementLimit("slip_energy", lim.max_slip_energy_j)]
        self.interlocks = tuple(items)

    def check(self, st: BenchStatus, eng: Engagements, now: float) -> list[Trip]:
        """The interlocks that trip now and were not active yet (they become active)."""
        trips = []
        for lock in self.interlocks:
            if lock.name in self.active:
                continue
            detail = lock.tripped(st, eng, now)
            if detail is not None:
                self.active[lock.name] = lock
                self._tripped_at[lock.name] = now
                trips.append(Trip(lock.name, detail, self.limits.action(lock.name)))
        return trips

    def alarm(self, st: BenchStatus, now: float) -> str | None:
        """An over-temperature active for `alarm_after_s` and still rising (more than ALARM_RISE_K over the last
        ALARM_WINDOW_S): heat the safe state does not stop. Keeps each active one's recent readings."""
        for name in [n for n in self._recent if n not in self.active]:
            del self._recent[name]
        for lock in self.active.values():
            if not isinstance(lock, OverTemperature) or not math.isfinite(value := getattr(st, lock.channel)):
                continue
            recent = self._recent.setdefault(lock.name, collections.deque())
            recent.append((now, value))
            while recent[0][0] < now - ALARM_WINDOW_S:
                recent.popleft()
            t_first = self._tripped_at.get(lock.name, now)
            if now - t_first >= self.limits.alarm_after_s and value - recent[0][1] > ALARM_RISE_K:
                return (f"{lock.name}: {lock.channel} {value:.1f} degC, still rising {value - recent[0][1]:.1f} K in "
                        f"{now - recent[0][0]:.0f} s, {now - t_first:.0f} s after the trip")
        return None

    def release(self, st: BenchStatus, eng: Engagements, now: float) -> bool:
        """Drop the active interlocks whose cause has cleared; True once none is left."""
        for name in [n for n, lock in self.active.items() if lock.cleared(st, eng, now)]:
            del self.active[name]
        return not self.active
