"""The bench's limits: what a schedule may ask for (checked before anything moves) and the interlocks.

Set-point limits are checked against the planned schedule by `check_schedule` (`benchlab run --dry-run`
and before every run). Interlock limits hold whatever the protocol does: the runner watches them while
running and puts the bench in its safe state (clutch open at zero torque, load torque zero, engine at
idle) when one is crossed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

from benchlab.bounds import MAX_CYCLES, MAX_RUN_DURATION_S
from benchlab.drivetrain import RPM, DrivetrainFacts
from benchlab.values import check_keys, positive_number
from protocols.safety import DEFAULT_REACTIONS, Reaction, reaction_of
from protocols.schedule import CONDITION_CHANNELS, OPERATORS, PHASES, Step, duration_s

ACTIONS = ("hold", "abort")
# A reading older than this (s) is an unknown reading: its `stale_<channel>` interlock trips. The node's radio
# loses a few frames in a row routinely (seconds), the scanner reads every 0.2 s and may time out once (2 s),
# the status frames come every 10 ms.
DEFAULT_MAX_AGE_S = {"T_flywheel": 10.0, "T_air": 5.0, "engine_speed": 0.5, "clutch_speed": 0.5, "clutch_torque": 0.5}
# What the sensors and materials allow a [limits] value to be (checked with `BenchLimits.check_physics`, issue 29)
MAX_FLYWHEEL_LIMIT_C = 400.0  # a flywheel and its facing beyond this: the friction material is gone
MAX_AIR_LIMIT_C = 200.0  # the chamber's seals, bearings and cabling
MIN_TEMPERATURE_LIMIT_C = 30.0  # a limit at room temperature trips before anything runs
MAX_CLEAR_MARGIN_K = 50.0
MAX_SLIP_TIME_LIMIT_S = 60.0  # one engagement slipping longer is no launch but a brake test
MAX_HOLD_S = 3600.0  # resume_after_s and the wait for an interlock to clear
ALARM_WINDOW_S, ALARM_RISE_K = 10.0, 1.0  # "still rising": up more than 1 K over the last 10 s
MAX_AGE_LIMIT_S = 60.0  # an age beyond this would leave the bench blind for too long: refused in BENCH.toml
# A launch must carry its load with this much torque to spare (clutch torque x gear ratio >= load x margin): the
# actuator's torque error and the drivetrain's drag eat into a bare 1.0, and a launch that cannot synchronise slips
# until its slip-time limit (protocols.limits.launch_problem)
LAUNCH_TORQUE_MARGIN = 1.1
SYNC_SEEN_S = 0.05  # the runner sees synchronism a few fast ticks after it happens (engine.Runner._run_step)
INTERLOCKS = ("flywheel_over_temperature", "air_over_temperature", "controller_lost",
              *(f"stale_{channel}" for channel in DEFAULT_MAX_AGE_S), "slip_time", "slip_energy")


@dataclass(frozen=True)
class BenchLimits:
    """Set-point ranges and interlock thresholds (defaults fit the simulated bench and the paper's protocols)."""

    max_engine_speed_rpm: float = 3000.0
    idle_speed_rpm: float = 800.0
    max_clutch_torque_nm: float = 100.0
    max_load_torque_nm: float = 600.0
    # interlocks
    max_flywheel_c: float = 110.0
    max_air_c: float = 80.0
    max_age_s: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_MAX_AGE_S))
    max_slip_time_s: float = 15.0
    max_slip_energy_j: float = 150e3
    heartbeat: bool = True  # a controller's heartbeat lost (the CAN driver's watchdog) trips an interlock
    on_interlock: str = "hold"  # "hold": safe state, hold until clear + resume_after_s, next cycle; "abort"
    actions: Mapping[str, str] = field(default_factory=dict)  # per interlock name, overriding on_interlock
    # per interlock name, the safe states to command in order (protocols/safety.py; [limits.actions] tables)
    reactions: Mapping[str, Reaction] = field(default_factory=lambda: dict(DEFAULT_REACTIONS))
    resume_after_s: float = 30.0
    clear_margin_k: float = 10.0  # an over-temperature clears this far below its limit
    # an over-temperature still rising (faster than ALARM_RISE_K per ALARM_WINDOW_S) this long after it tripped, the
    # bench safe, is heat the bench cannot switch off (an external heater): the run aborts with an alarm
    alarm_after_s: float = 60.0
    max_wait_s: float = 1800.0  # "hold" gives up (abort) after this long
    # the bench's drivetrain (BENCH.toml [drivetrain]), for the launch estimates; not a [limits] key
    drivetrain: DrivetrainFacts = DrivetrainFacts()

    def __post_init__(self) -> None:
        object.__setattr__(self, "max_age_s", {**DEFAULT_MAX_AGE_S, **self.max_age_s})
        object.__setattr__(self, "reactions", {**DEFAULT_REACTIONS, **self.reactions})

    def action(self, interlock: str) -> str:
        """What the named interlock does once its safe state holds: "hold" or "abort"."""
        return self.actions.get(interlock, self.on_interlock)

    def reaction(self, interlock: str) -> Reaction:
        """The safe states the named interlock commands, in order (protocols/safety.py)."""
        return self.reactions[interlock]

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "<limits>", prefix: str = "limits") -> "BenchLimits":
        """Build from a config table, raising InputError naming the first bad field."""
        from benchlab.errors import InputError

        known = {f.name: f for f in fields(cls) if f.name not in ("drivetrain", "reactions")}
        check_keys(source, prefix, values, known)
        clean: dict[str, Any] = {}
        for key, value in values.items():
            if key == "max_age_s":
                clean[key] = _table(value, DEFAULT_MAX_AGE_S, source, f"{prefix}.{key}", _age)
                continue
            if key == "actions":  # per interlock "hold"/"abort", or a table: then, stages, escalate_after_s
                entries = _table(value, INTERLOCKS, source, f"{prefix}.{key}", _action_entry)
                clean[key] = {k: v[0] for k, v in entries.items() if v[0] is not None}
                clean["reactions"] = {k: v[1] for k, v in entries.items() if v[1] is not None}
                continue
            default = known[key].default
            if isinstance(default, bool):
                if not isinstance(value, bool):
                    raise InputError(source, f"{prefix}.{key}", f"true or false, got {value!r}")
            elif isinstance(default, str):
                _action(value, source, f"{prefix}.{key}")
            elif positive_number(value) is None:
                raise InputError(source, f"{prefix}.{key}", f"a positive number, got {value!r}")
            clean[key] = float(value) if isinstance(default, float) else value
        return cls(**clean)

    def check_physics(self, source: str, setpoint_max: Mapping[str, float], prefix: str = "limits") -> None:
        """The limits against each other, the DBC's set-point ranges (`setpoint_max`: logical set-point key ->
        largest value its signal carries) and what the sensors and materials allow; InputError naming the key and
        the rule (a limit `1e300` would switch its interlock off; idle above the maximum speed commands it)."""
        from benchlab.errors import InputError

        drive, clutch, load = (setpoint_max[k] for k in ("drive.speed_setpoint", "clutch.torque_setpoint",
                                                         "load.torque_setpoint"))
        rules = (
            ("idle_speed_rpm", self.idle_speed_rpm < self.max_engine_speed_rpm,
             f"below max_engine_speed_rpm ({self.max_engine_speed_rpm:g})"),
            ("max_engine_speed_rpm", self.max_engine_speed_rpm <= drive, f"at most the DBC's {drive:g} rpm"),
            ("max_clutch_torque_nm", self.max_clutch_torque_nm <= clutch, f"at most the DBC's {clutch:g} N*m"),
            ("max_load_torque_nm", self.max_load_torque_nm <= load, f"at most the DBC's {load:g} N*m"),
            ("max_flywheel_c", MIN_TEMPERATURE_LIMIT_C <= self.max_flywheel_c <= MAX_FLYWHEEL_LIMIT_C,
             f"a flywheel limit from {MIN_TEMPERATURE_LIMIT_C:g} to {MAX_FLYWHEEL_LIMIT_C:g} degC (the friction "
             f"material)"),
            ("max_air_c", MIN_TEMPERATURE_LIMIT_C <= self.max_air_c <= MAX_AIR_LIMIT_C,
             f"a chamber air limit from {MIN_TEMPERATURE_LIMIT_C:g} to {MAX_AIR_LIMIT_C:g} degC (seals, bearings)"),
            ("clear_margin_k", self.clear_margin_k <= MAX_CLEAR_MARGIN_K, f"at most {MAX_CLEAR_MARGIN_K:g} K"),
            ("max_slip_time_s", self.max_slip_time_s <= MAX_SLIP_TIME_LIMIT_S, f"at most {MAX_SLIP_TIME_LIMIT_S:g} s"),
            ("max_slip_energy_j", self.max_slip_energy_j <= self.max_clutch_torque_nm * self.max_engine_speed_rpm
             * RPM * self.max_slip_time_s, "at most max_clutch_torque_nm x max_engine_speed_rpm x max_slip_time_s "
             f"({self.max_clutch_torque_nm * self.max_engine_speed_rpm * RPM * self.max_slip_time_s:.0f} J)"),
            ("resume_after_s", self.resume_after_s <= MAX_HOLD_S, f"at most {MAX_HOLD_S:g} s"),
            ("max_wait_s", self.max_wait_s <= MAX_HOLD_S, f"at most {MAX_HOLD_S:g} s"),
            ("alarm_after_s", ALARM_WINDOW_S <= self.alarm_after_s <= self.max_wait_s,
             f"from {ALARM_WINDOW_S:g} s to max_wait_s ({self.max_wait_s:g} s)"),
        )
        for key, ok, expected in rules:
            if not ok:
                raise InputError(source, f"{prefix}.{key}", f"{expected}, got {getattr(self, key)!r}")

    def as_dict(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}


def _plain(value: Any) -> Any:
    """A limits field as JSON-ready data (tables as dicts, a Reaction or the drivetrain as its fields)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, Reaction):
        return value.as_dict()
    return dict(value.__dict__) if isinstance(value, DrivetrainFacts) else value


def _table(value: Any, keys: Any, source: str, name: str, check: Any) -> dict[str, Any]:
    """A sub-table of [limits] whose keys come from `keys`, each value passed through `check`."""
    from benchlab.errors import InputError

    if not isinstance(value, Mapping):
        raise InputError(source, name, f"a table, got {value!r}")
    check_keys(source, name, value, keys)
    return {key: check(v, source, f"{name}.{key}") for key, v in value.items()}


def _age(value: Any, source: str, name: str) -> float:
    from benchlab.errors import InputError

    age = positive_number(value)
    if age is None or age > MAX_AGE_LIMIT_S:
        raise InputError(source, name, f"an age in s, more than 0 and at most {MAX_AGE_LIMIT_S:g}, got {value!r}")
    return age


def _action(value: Any, source: str, name: str) -> str:
    from benchlab.errors import InputError

    if value not in ACTIONS:
        raise InputError(source, name, f"one of {', '.join(ACTIONS)}, got {value!r}")
    return value


def _action_entry(value: Any, source: str, name: str) -> tuple[str | None, Reaction | None]:
    """One `[limits.actions]` entry: "hold"/"abort", or a table with `then` and the reaction's keys."""
    if isinstance(value, Mapping):
        then = value.get("then")
        return (None if then is None else _action(then, source, f"{name}.then")), reaction_of(value, source, name)
    return _action(value, source, name), None


def launch_estimate(step: Step, limits: BenchLimits) -> tuple[float, float, bool]:
    """(slip time s, slip energy J, synchronises) of a launch from standstill with constant torques."""
    omega = step.engine_speed_rpm * RPM
    reaction = step.load_torque_nm / limits.drivetrain.gear_ratio
    inertia = limits.drivetrain.inertia_at_clutch
    net = step.clutch_torque_nm - reaction
    if net > 0:
        t_sync = omega * inertia / net
        if t_sync <= step.duration_s:
            return t_sync, step.clutch_torque_nm * omega * t_sync / 2.0, True
    t = step.duration_s
    if net > 0:  # slows down the slip even if it does not finish
        slip_end = omega - net / inertia * t
        return t, step.clutch_torque_nm * (omega + slip_end) / 2.0 * t, False
    return t, step.clutch_torque_nm * omega * t, False


def launch_problem(step: Step, limits: BenchLimits) -> str | None:
    """Why a launch cannot synchronise (None: it can): the clutch's torque seen at the load (x gear ratio) must
    exceed the load torque by LAUNCH_TORQUE_MARGIN, and synchronism come within the step's maximum slip time.

    A launch that cannot synchronise slips until `slip_time_limit` and its cycle's drive stays open: no launch."""
    ratio = limits.drivetrain.gear_ratio
    transmitted, needed = step.clutch_torque_nm * ratio, abs(step.load_torque_nm) * LAUNCH_TORQUE_MARGIN
    if not transmitted >= needed:
        return (f"cannot synchronise: clutch {step.clutch_torque_nm:g} N*m x gear ratio {ratio:g} = {transmitted:g} N*m"
                f" below load {step.load_torque_nm:g} N*m x margin {LAUNCH_TORQUE_MARGIN:g} = {needed:g} N*m")
    _, _, synchronises = launch_estimate(step, limits)
    if not synchronises:
        return f"cannot synchronise within its {step.duration_s:g} s maximum slip time"
    return None


def with_launch_estimates(steps: Sequence[Step], limits: BenchLimits) -> tuple[Step, ...]:
    """The schedule with each launch's expected duration (`estimate_s`) its time to synchronise on this drivetrain
    (launch_estimate, plus the tick the runner takes to see it): what the plan's duration and a run's progress count,
    instead of the maximum slip time a launch that synchronises never uses."""
    return tuple(replace(s, estimate_s=round(min(s.duration_s, launch_estimate(s, limits)[0] + SYNC_SEEN_S), 3))
                 if s.phase == "launch" else s for s in steps)


@dataclass(frozen=True)
class ScheduleProblem:
    """One thing a schedule asks that the bench must not do: its step (None: the whole schedule), the Step field
    it is about (e.g. "engine_speed_rpm", "until[0].value") and the line that says why."""

    step: int | None
    field: str
    text: str

    def __str__(self) -> str:
        return self.text


def check_schedule(steps: Sequence[Step], limits: BenchLimits) -> list[str]:
    """Problems of a schedule against the limits, one line each (empty: the schedule may run)."""
    return [p.text for p in schedule_problems(steps, limits)]


def schedule_problems(steps: Sequence[Step], limits: BenchLimits) -> list[ScheduleProblem]:
    """Problems of a schedule against the limits, each naming its step and field (empty: the schedule may run).

    Every comparison is written so that NaN fails it: an unknown set-point is never within the limits.
    """
    problems: list[ScheduleProblem] = []
    for i, s in enumerate(steps):
        where = f"step {i} (cycle {s.cycle}, {s.phase})"

        def add(field: str, text: str) -> None:
            problems.append(ScheduleProblem(i, field, f"{where}: {text}"))

        if s.phase not in PHASES:
            add("phase", f"unknown phase {s.phase!r}")
            continue
        if not (0.0 <= s.engine_speed_rpm <= limits.max_engine_speed_rpm):
            add("engine_speed_rpm", f"engine speed {s.engine_speed_rpm:g} rpm outside 0..{limits.max_engine_speed_rpm:g}")
        if not (0.0 <= s.clutch_torque_nm <= limits.max_clutch_torque_nm):
            add("clutch_torque_nm", f"clutch torque {s.clutch_torque_nm:g} N*m outside 0..{limits.max_clutch_torque_nm:g}")
        if not abs(s.load_torque_nm) <= limits.max_load_torque_nm:
            add("load_torque_nm", f"load torque {s.load_torque_nm:g} N*m beyond ±{limits.max_load_torque_nm:g}")
        if not -1 <= s.cycle <= MAX_CYCLES:
            add("cycle", f"cycle {s.cycle} outside -1..{MAX_CYCLES} (benchlab.bounds)")
        if not 0 < s.duration_s <= MAX_RUN_DURATION_S:
            add("duration_s", f"duration {s.duration_s!r} s outside (0, {MAX_RUN_DURATION_S:g}]")
        if s.estimate_s is not None and not 0 <= s.estimate_s <= MAX_RUN_DURATION_S:
            add("estimate_s", f"estimated duration {s.estimate_s!r} s outside 0..{MAX_RUN_DURATION_S:g}")
        if s.phase == "launch":
            t, energy, _ = launch_estimate(s, limits)
            if not s.duration_s <= limits.max_slip_time_s:
                add("duration_s", f"slip time up to {s.duration_s:g} s beyond the {limits.max_slip_time_s:g} s limit")
            if not energy <= limits.max_slip_energy_j:
                add("clutch_torque_nm", f"slip energy up to {energy / 1e3:.0f} kJ beyond the "
                                        f"{limits.max_slip_energy_j / 1e3:.0f} kJ limit")
            why = launch_problem(s, limits)
            if why is not None:
                add("clutch_torque_nm", f"launch {why}")
        if s.phase == "heat":
            energy = s.clutch_torque_nm * s.engine_speed_rpm * RPM * s.pulse_s
            if not (0 < s.pulse_s <= limits.max_slip_time_s):
                add("pulse_s", f"heat pulse {s.pulse_s:g} s outside 0..{limits.max_slip_time_s:g} s")
            if not energy <= limits.max_slip_energy_j:
                add("pulse_s", f"heat pulse energy {energy / 1e3:.0f} kJ beyond the "
                               f"{limits.max_slip_energy_j / 1e3:.0f} kJ limit")
            if not s.rest_s > 0:
                add("rest_s", "heat pulses need a rest between them (rest_s > 0)")
            if not s.clutch_torque_nm < s.load_torque_nm / limits.drivetrain.gear_ratio:
                add("load_torque_nm", f"load torque {s.load_torque_nm:g} N*m cannot hold the output against "
                                      f"{s.clutch_torque_nm:g} N*m clutch torque")
        for j, c in enumerate(s.until):
            if c.channel not in CONDITION_CHANNELS:
                add(f"until[{j}].channel",
                    f"condition channel {c.channel!r} not one of {', '.join(CONDITION_CHANNELS)}")
            if c.op not in OPERATORS:
                add(f"until[{j}].op", f"condition operator {c.op!r} not one of {', '.join(OPERATORS)}")
            limit = {"T_flywheel": limits.max_flywheel_c, "T_air": limits.max_air_c}.get(c.channel)
            if limit is not None and c.op in (">=", "steady") and not c.value + c.band_k <= limit - limits.clear_margin_k:
                add(f"until[{j}].value", f"target {c.channel} {c.value:g} too close to its interlock at {limit:g}")
    planned = duration_s(tuple(steps))
    if not planned <= MAX_RUN_DURATION_S:
        problems.append(ScheduleProblem(None, "duration_s", f"planned duration {planned:.0f} s beyond the longest run a "
                                        f"bench does, {MAX_RUN_DURATION_S:.0f} s (benchlab.bounds)"))
    return problems
