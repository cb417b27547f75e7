"""What the bench does when an interlock trips: safe states, and per interlock the ones to take in order (issue 29).

One fixed safe state cannot fit every fault: idling the drive against a clutch that does not open heats it. Each
interlock therefore has a `Reaction`: the safe states to command in order, and how long friction power may still
be measured after one before the next is commanded (escalation). `BenchLimits.reaction` gives an interlock's
reaction, the defaults below overridden by `[limits.actions]` in BENCH.toml; the runner commands them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

# Friction power (W) above this, measured from fresh status frames, means the clutch still slips: the safe state
# commanded did not work. An open clutch reports no slipping state, so its friction power is exactly 0.
FRICTION_POWER_SEEN_W = 50.0
MAX_ESCALATE_AFTER_S = 10.0  # a reaction that waits longer lets a stuck clutch dissipate too much: refused


@dataclass(frozen=True)
class SafeState:
    """The set-points of one safe state: the clutch always open; the drive at idle or stopped (0 rpm); the load
    machine at zero torque or holding the torque it last held."""

    name: str
    engine: str  # "idle" or "stop"
    load: str  # "zero" or "hold"


SAFE_STATES = {s.name: s for s in (
    SafeState("open_idle", "idle", "zero"),  # the clutch cools, the drive turning the flywheel's air
    SafeState("open_stop", "stop", "zero"),
    SafeState("stop_hold", "stop", "hold"),  # a clutch that does not open: nothing left turning against it
)}
SEVERITY = tuple(SAFE_STATES)  # of several safe states asked for at once, the one furthest in this order holds
OPEN_IDLE = SAFE_STATES["open_idle"]


@dataclass(frozen=True)
class Reaction:
    """An interlock's safe states in order: the next one when friction power is still measured `escalate_after_s`
    after the previous one was commanded; friction power still measured after the last aborts with an alarm."""

    stages: tuple[str, ...]
    escalate_after_s: float = 2.0

    def as_dict(self) -> dict[str, Any]:
        return {"stages": list(self.stages), "escalate_after_s": self.escalate_after_s}


_COOL = Reaction(("open_idle", "stop_hold"))  # over-temperature, lost input: open, idle, cool; stuck: stop
#: The defaults a bench engineer signs: an over-temperature or a lost instrument or node opens the clutch and idles
#: (no new engagement until it clears); a lost drive opens and releases the load; a lost clutch actuator (its state
#: unknown) stops the drive; every reaction stops the drive with the load holding when the clutch does not open.
DEFAULT_REACTIONS: Mapping[str, Reaction] = {
    "flywheel_over_temperature": _COOL, "air_over_temperature": _COOL, "controller_lost": _COOL,
    "stale_T_flywheel": _COOL, "stale_T_air": _COOL, "stale_clutch_speed": _COOL,
    "stale_engine_speed": Reaction(("open_stop", "stop_hold")),
    "stale_clutch_torque": Reaction(("stop_hold",)),
    "slip_time": _COOL, "slip_energy": _COOL,
}


def strongest(names: "list[str] | tuple[str, ...]") -> SafeState:
    """The safe state that satisfies all of `names` (the furthest in SEVERITY); open_idle for none."""
    return SAFE_STATES[max(names, key=SEVERITY.index)] if names else OPEN_IDLE


def reaction_of(value: Any, source: str, name: str) -> Reaction:
    """A `[limits.actions]` table's reaction (`stages`, `escalate_after_s`), checked; InputError naming the key."""
    from benchlab.errors import InputError
    from benchlab.values import check_keys, positive_number

    check_keys(source, name, value, ("then", "stages", "escalate_after_s"))
    stages = value.get("stages", ["open_idle", "stop_hold"])
    if (not isinstance(stages, list) or not stages or any(s not in SAFE_STATES for s in stages)
            or len(set(stages)) != len(stages)):
        raise InputError(source, f"{name}.stages", f"a list of distinct safe states from {', '.join(SAFE_STATES)}, "
                                                   f"got {stages!r}")
    if stages[-1] != "stop_hold":
        raise InputError(source, f"{name}.stages", f"a list ending in stop_hold (a clutch that does not open must "
                                                   f"stop the drive), got {stages!r}")
    after = value.get("escalate_after_s", 2.0)
    if positive_number(after) is None or after > MAX_ESCALATE_AFTER_S:
        raise InputError(source, f"{name}.escalate_after_s", f"a time in s, more than 0 and at most "
                                                             f"{MAX_ESCALATE_AFTER_S:g}, got {after!r}")
    return Reaction(tuple(stages), float(after))
