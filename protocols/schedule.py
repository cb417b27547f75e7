"""Protocols as data: a schedule of load cycles and cool-downs that can be printed, checked and timed.

A schedule is a tuple of Steps; each Step holds set-points for a duration, the way the bench
controllers hold them (engine speed by the drive motor, clutch torque by the actuator, load
torque by the load machine). Nothing here moves hardware.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any, NamedTuple

from benchlab.values import finite_number

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

    def steady_over(self, times: Any, values: Any, now: float) -> bool:
        """The "steady" test on the channel's samples (`times`, `values`: arrays, oldest first) seen up to `now`:
        false until they span the window."""
        import numpy as np

        if len(times) == 0 or now - times[0] < self.window_s:
            return False
        window = times >= now - self.window_s
        second = times >= now - self.window_s / 2
        first = window & ~second
        if not first.any() or not second.any():
            return False
        return (abs(float(np.mean(values[window])) - self.value) <= self.band_k
                and abs(float(np.mean(values[second])) - float(np.mean(values[first]))) <= self.drift_k)

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
        """Expected duration: the step's estimate (a closed-loop step's, a launch's time to synchronise) where it
        has one, else its duration."""
        return float(self.estimate_s if self.estimate_s is not None else self.duration_s)


PHASES = ("launch", "drive", "open", "heat")


def pulse_due(flywheel_c: float, target_c: float, last_rise_k: float) -> bool:
    """A "heat" step's rule for starting a pulse: the flywheel below the target by more than half the last pulse's
    rise, so that the saw-tooth the pulses leave is centred on the target."""
    return flywheel_c < target_c - last_rise_k / 2.0


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
    """Planned duration: each step's expected duration (a launch's time to synchronise where the plan estimated it,
    protocols.limits.with_launch_estimates; else its maximum slip time)."""
    return float(sum(step.expected_s for step in steps))


class StepFieldError(ValueError):
    """A stored step that is not a Step: `field` names the entry (e.g. "until[0].value"; "" the step itself),
    `expected` what it should be."""

    def __init__(self, field: str, expected: str) -> None:
        self.field, self.expected = field, expected
        super().__init__(f"{field}: {expected}")


def _number(value: Any, field: str) -> float:
    number = finite_number(value)
    if number is None:
        raise StepFieldError(field, f"a finite number, got {value!r}")
    return number


def _optional_number(value: Any, field: str) -> float | None:
    return None if value is None else _number(value, field)


def _integer(value: Any, field: str) -> int:
    number = finite_number(value)
    if number is None or not number.is_integer():
        raise StepFieldError(field, f"an integer, got {value!r}")
    return int(number)


def _text(value: Any, field: str) -> str:
    if not isinstance(value, str):
        raise StepFieldError(field, f"a string, got {value!r}")
    return value


def _list(value: Any, field: str) -> list[Any]:
    if not isinstance(value, (list, tuple)):
        raise StepFieldError(field, f"a list, got {value!r}")
    return list(value)


def _conditions(value: Any, field: str) -> tuple[Condition, ...]:
    return tuple(_dataclass_from(Condition, c, f"{field}[{i}]") for i, c in enumerate(_list(value, field)))


def _point(value: Any, field: str) -> tuple[tuple[str, float], ...]:
    pairs = []
    for i, pair in enumerate(_list(value, field)):
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise StepFieldError(f"{field}[{i}]", f"a pair [name, number], got {pair!r}")
        pairs.append((_text(pair[0], f"{field}[{i}][0]"), _number(pair[1], f"{field}[{i}][1]")))
    return tuple(pairs)


#: How each annotated field type of Step and Condition is read back from JSON.
_READERS: dict[str, Callable[[Any, str], Any]] = {
    "str": _text, "float": _number, "int": _integer, "float | None": _optional_number,
    "tuple[Condition, ...]": _conditions, "tuple[tuple[str, float], ...]": _point}


def _dataclass_from(cls: type, row: Any, where: str) -> Any:
    """`cls(**row)` with every key known, every field without a default present and every value of its type."""
    prefix = f"{where}." if where else ""
    known = {f.name: f for f in fields(cls)}
    if not isinstance(row, dict):
        raise StepFieldError(where, f"an object with the fields {', '.join(known)}, got {row!r}")
    for key in row:
        if key not in known:
            raise StepFieldError(f"{prefix}{key}", f"one of {', '.join(known)} (unknown field)")
    values = {}
    for name, f in known.items():
        if name in row:
            values[name] = _READERS[str(f.type)](row[name], f"{prefix}{name}")
        elif f.default is MISSING and f.default_factory is MISSING:
            raise StepFieldError(f"{prefix}{name}", "present (missing)")
    return cls(**values)


def step_from_dict(row: Any) -> Step:
    """Inverse of `Step.as_dict` (JSON round trip), checked: StepFieldError names the first field that is unknown,
    missing or not of its type (numbers finite), so a stored schedule never reaches the bench half-read."""
    return _dataclass_from(Step, row, "")


def steps_from_rows(rows: Any, source: str) -> tuple[Step, ...]:
    """A stored schedule (a list of `Step.as_dict` rows) read back; InputError naming `source`, step and field."""
    from benchlab.errors import InputError

    if not isinstance(rows, list):
        raise InputError(source, "/schedule", f"a list of steps, got {type(rows).__name__}")
    steps = []
    for i, row in enumerate(rows):
        try:
            steps.append(step_from_dict(row))
        except StepFieldError as exc:
            raise InputError(source, f"/schedule step {i} {exc.field}".rstrip(), exc.expected) from None
    return tuple(steps)


def describe(steps: tuple[Step, ...]) -> list[str]:
    """One line per step, for --dry-run (units as people read them: benchlab.units.display)."""
    from benchlab.units import display

    nm, lines = display("N*m"), []
    for i, s in enumerate(steps):
        extra = ""
        if s.phase == "heat":
            extra += f" pulses {s.pulse_s:g} s on / {s.rest_s:g} s off"
        if s.until:
            extra += " until " + " or ".join(c.describe() for c in s.until) + f" (time-out {s.duration_s:g} s)"
        if s.label:
            extra += f" [{s.label}]"
        lines.append(f"{i:4d} cycle {s.cycle:3d} {s.phase:6s} {s.expected_s:7.1f} s  engine {s.engine_speed_rpm:6.0f} rpm"
                     f"  clutch {s.clutch_torque_nm:5.1f} {nm}  load {s.load_torque_nm:6.1f} {nm}{extra}")
    return lines
