"""Protocols as data: a schedule of load cycles and cool-downs that can be printed, checked and timed.

A schedule is a tuple of Steps; each Step holds set-points for a duration, the way the bench
controllers hold them (engine speed by the drive motor, clutch torque by the actuator, load
torque by the load machine). Nothing here moves hardware.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import NamedTuple

#: Condition operators: a channel reaching a value, or settling at it.
OPERATORS = (">=", "<=", "steady")
#: Channels a condition may watch: what the runner knows while the bench runs (benchlab.runner.devices.BenchStatus).
CONDITION_CHANNELS = ("T_flywheel", "T_air")


@dataclass(frozen=True)
class Condition:
    """Ends a step once it holds: `channel op value` on the measured /aligned channel.

    "steady": over the last `window_s` the channel's mean is within `band_k` of `value` and the means of
    the window's two halves differ by at most `drift_k` (a stated, testable steadiness criterion).
    """

    channel: str
    op: str
    value: float
    band_k: float = 1.0
    window_s: float = 120.0
    drift_k: float = 0.3

    def describe(self) -> str:
        if self.op == "steady":
            return (f"{self.channel} steady at {self.value:g} (mean of {self.window_s:g} s within ±{self.band_k:g},"
                    f" drift <= {self.drift_k:g})")
        return f"{self.channel} {self.op} {self.value:g}"


@dataclass(frozen=True)
class Step:
    """Set-points held for `duration_s`; `phase` names it for events and summaries.

    phase "launch" clamps the clutch at `clutch_torque_nm` until synchronous (or a slip limit);
    "drive" keeps it clamped and locked (open if the launch did not synchronise); "open" opens it;
    "heat" slips in pulses of `pulse_s` at `clutch_torque_nm` with `rest_s` open between them, a pulse
    starting only while the flywheel is below the step's steady target (the output held by the load);
    the load machine applies `load_torque_nm`.

    Closed-loop steps end at the first of `until` that holds; `duration_s` is then their time-out and
    `estimate_s` the expected duration. `label` marks steps for analysis (e.g. "cooldown"), `point` holds
    the operating point they belong to.
    """

    phase: str
    duration_s: float
    engine_speed_rpm: float
    clutch_torque_nm: float = 0.0
    load_torque_nm: float = 0.0
    cycle: int = -1
    until: tuple[Condition, ...] = ()
    estimate_s: float | None = None
    pulse_s: float = 0.0
    rest_s: float = 0.0
    label: str = ""
    point: tuple[tuple[str, float], ...] = field(default=())

    def as_dict(self) -> dict[str, float | str | int]:
        return asdict(self)

    @property
    def closed_loop(self) -> bool:
        return bool(self.until)

    @property
    def expected_s(self) -> float:
        """Expected duration: the estimate of a closed-loop step, else its duration."""
        return float(self.estimate_s if self.closed_loop and self.estimate_s is not None else self.duration_s)


PHASES = ("launch", "drive", "open", "heat")


class Setpoints(NamedTuple):
    """What the controllers are told during a step (the arguments of the bench's `command`)."""

    engine_speed_rpm: float
    clutch_torque_nm: float
    clutch_open: bool
    load_torque_nm: float


def setpoints(step: Step, synchronised: bool = True, pulse_on: bool = False) -> Setpoints:
    """The set-points of `step` (its phase's meaning, see `Step`): the one step interpreter.

    `synchronised`: the cycle's launch reached synchronous speed (else "drive" keeps the clutch open);
    `pulse_on`: a "heat" step is inside one of its pulses. The runner and the batch simulator both play
    schedules through this.
    """
    clamped = (step.phase == "launch" or (step.phase == "drive" and synchronised)
               or (step.phase == "heat" and pulse_on))
    return Setpoints(step.engine_speed_rpm, step.clutch_torque_nm if clamped else 0.0, not clamped,
                     step.load_torque_nm)


def duration_s(steps: tuple[Step, ...]) -> float:
    """Planned duration; a launch's duration is its maximum slip time, a closed-loop step's its estimate."""
    return float(sum(step.expected_s for step in steps))


def step_from_dict(row: dict) -> Step:
    """Inverse of `Step.as_dict` (JSON round trip: lists back to tuples)."""
    row = dict(row)
    row["until"] = tuple(Condition(**c) for c in row.get("until", ()))
    row["point"] = tuple((str(k), float(v)) for k, v in row.get("point", ()))
    return Step(**row)


def describe(steps: tuple[Step, ...]) -> list[str]:
    """One line per step, for --dry-run."""
    lines = []
    for i, s in enumerate(steps):
        extra = ""
        if s.phase == "heat":
            extra += f" pulses {s.pulse_s:g} s on / {s.rest_s:g} s off"
        if s.until:
            extra += " until " + " or ".join(c.describe() for c in s.until) + f" (time-out {s.duration_s:g} s)"
        if s.label:
            extra += f" [{s.label}]"
        lines.append(f"{i:4d} cycle {s.cycle:3d} {s.phase:6s} {s.expected_s:7.1f} s  engine {s.engine_speed_rpm:6.0f} rpm"
                     f"  clutch {s.clutch_torque_nm:5.1f} N*m  load {s.load_torque_nm:6.1f} N*m{extra}")
    return lines
