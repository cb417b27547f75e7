"""What a run file holds (contract section 1, docs/runfile.md): schema, channels and their units, the tables'
columns, and what a stored value may be. Only numpy: the writer, the readers and the devices' layout share it."""

from __future__ import annotations

import numpy as np

SCHEMA = "benchlab-run/1"
#: Every channel the contract names, with its unit; the first ten are required.
ALIGNED_UNITS: dict[str, str] = {
    "time": "s", "engine_speed": "rpm", "clutch_speed": "rpm", "clutch_torque": "N*m", "clutch_state": "1",
    "friction_power": "W", "T_flywheel": "degC", "T_air": "degC", "T_housing": "degC", "T_ambient": "degC",
    "T_engine": "degC", "load_torque": "N*m", "T_flywheel_1": "degC", "T_flywheel_2": "degC",
}
REQUIRED = tuple(list(ALIGNED_UNITS)[:10])
#: What each contract channel is (contract section 1): the comment an export gives the channel.
ALIGNED_MEANING: dict[str, str] = {
    "time": "time since run start, uniform step dt",
    "engine_speed": "ω_e, engine-side (drive motor) speed",
    "clutch_speed": "ω_c, transmission input shaft speed; slip Δω = ω_e − ω_c",
    "clutch_torque": "T_c, torque transmitted by the clutch",
    "clutch_state": "S: 1 clamped (engaged or slipping), 0 open",
    "friction_power": "P = T_c · Δω, Δω in rad/s (eq. 4); 0 when not slipping",
    "T_flywheel": "ϑ_F, mean of the flywheel sensors", "T_air": "ϑ_A, clutch-chamber air",
    "T_housing": "ϑ_T, transmission housing", "T_ambient": "ϑ_amb, ambient", "T_engine": "ϑ_eng, engine",
    "load_torque": "load machine torque", "T_flywheel_1": "flywheel sensor 1", "T_flywheel_2": "flywheel sensor 2",
}

#: The named states of a channel that holds states, as words a sentence can use ("runs ... with the clutch open").
ALIGNED_LEVELS: dict[str, dict[float, str]] = {"clutch_state": {1.0: "the clutch clamped", 0.0: "the clutch open"}}


def aligned_description(name: str, source: "dict | None" = None) -> str:
    """The `description` an /aligned dataset carries (and an export shows as its comment): what the contract
    channel is, and where its values came from (`source`: a raw stream's column and scale, as the acquisition
    layout describes it, or the `from` text of an imported channel)."""
    parts = [ALIGNED_MEANING[name]] if name in ALIGNED_MEANING else []
    if source and "stream" in source:
        scale = f" × {source['scale']:g}" if source.get("scale", 1.0) != 1.0 else ""
        parts.append(f"from {source['stream']}.{source['column']}{scale}, held on the grid")
    elif source and "from" in source:
        parts.append(f"from {source['from']}")
    return "; ".join(parts)


EVENT_KIND_LEN = 32
EVENT_DETAIL_LEN = 160
EVENT_REASON_LEN = 32
#: /events: one dataset per column, in this order, as (dtype, units, value of a row not written). `cycle` and
#: `step` (the row of /schedule the event belongs to) are -1 outside a cycle or step; kind, detail and reason
#: are fixed-length UTF-8 text. `detail` is for people; `reason` is what a program matches: the interlock's
#: name for `interlock`, why the step ended (END_*) for `step_end` and `cooldown_end`, "" else.
EVENT_FIELDS: dict[str, tuple[str, str, object]] = {
    "time": ("f8", "s", float("nan")), "cycle": ("i8", "1", -1), "kind": (f"S{EVENT_KIND_LEN}", "", b""),
    "detail": (f"S{EVENT_DETAIL_LEN}", "", b""), "step": ("i8", "1", -1),
    "reason": (f"S{EVENT_REASON_LEN}", "", b"")}
EVENT_COLUMNS = tuple(EVENT_FIELDS)
#: The columns every /events holds; files written before `step` or `reason` existed lack them (read back as
#: benchlab.runfile.read.complete_events fills them).
EVENT_REQUIRED = ("time", "cycle", "kind", "detail")
#: Why a step ended (`reason` of step_end and cooldown_end): its time ran out, its `until` condition was met,
#: a launch reached synchronism.
END_TIME, END_CONDITION, END_SYNCHRONISED = "time", "condition", "synchronised"
#: /schedule: units of the Step fields that have one (the rest are stored with units "").
SCHEDULE_UNITS = {"duration_s": "s", "engine_speed_rpm": "rpm", "clutch_torque_nm": "N*m",
                  "load_torque_nm": "N*m", "cycle": "1", "estimate_s": "s", "pulse_s": "s", "rest_s": "s"}
#: /analysis/cooldowns: one dataset per column (`benchlab cooldown`), in this order.
COOLDOWN_UNITS = {"cycle": "1", "engine_speed": "rpm", "clutch_state": "1", "slip_speed": "rpm", "t_start": "s",
                  "t_end": "s", "R": "K/W", "R_se": "K/W", "R_u": "K/W", "T_P0": "degC", "T_P0_se": "K",
                  "rmse_K": "K", "n": "1", "chi2_red": "1", "R_true": "K/W"}
#: /analysis/eq11: units of the scalars (and of their `*_se`); any other scalar is "1".
EQ11_UNITS = {"a1": "K/W", "a2": "K/W", "R0": "K/W", "b1": "1/rpm", "b2": "1/rpm"}

TIME_TOLERANCE = 1e-6  # relative to dt
#: Values a dry-clutch bench can measure, per unit: anything beyond (1e300, inf) is a corrupt number, not a
#: measurement. Channels in other units are only checked for infinities.
MEASURABLE_RANGE: dict[str, tuple[float, float]] = {
    "rpm": (-1e5, 1e5), "N*m": (-1e5, 1e5), "W": (-1e8, 1e8), "degC": (-273.15, 1e4)}
#: Channels whose measurable values are narrower than their unit's: friction power is |T_c·Δω| (eq. 4), never
#: negative (a negative one used to be accepted and fed to the model as heat drawn out of the clutch).
CHANNEL_RANGE: dict[str, tuple[float, float]] = {"friction_power": (0.0, MEASURABLE_RANGE["W"][1])}
#: How far clutch_state (1 clamped, 0 open) may read from 0 or 1: measurement noise, not a third state.
CLUTCH_STATE_NOISE = 0.05


def unmeasurable_sample(name: str, unit: str, values: np.ndarray) -> tuple[int, str, float] | None:
    """The first sample that is neither NaN (not measured) nor a value the bench can measure in its unit
    (clutch_state: 0 or 1), as (index, what was expected, value); None when every sample is fine."""
    if name == "clutch_state":
        near = np.minimum(np.abs(values), np.abs(values - 1.0)) <= CLUTCH_STATE_NOISE
        expected = f"0 (open) or 1 (clamped) within ±{CLUTCH_STATE_NOISE:g}, or NaN"
    else:
        low, high = CHANNEL_RANGE.get(name) or MEASURABLE_RANGE.get(unit) or (-np.inf, np.inf)
        if _finite_within(values, low, high):
            return None
        if np.isfinite(low):
            near = (values >= low) & (values <= high)
            expected = f"values in [{low:g}, {high:g}] {unit} or NaN (not measured)"
        else:
            near = np.isfinite(values)
            expected = "finite values or NaN (not measured)"
    bad = np.flatnonzero(~near & ~np.isnan(values))
    return (int(bad[0]), expected, float(values[bad[0]])) if bad.size else None


def _finite_within(values: np.ndarray, low: float, high: float) -> bool:
    """Whether the samples measured (NaN ignored) are finite and within [low, high], from their extremes alone (one
    pass each, no mask of a run's length); False also where none is measured."""
    if not values.size:
        return False
    least, most = np.fmin.reduce(values), np.fmax.reduce(values)
    return bool(np.isfinite(least) and np.isfinite(most) and low <= least and most <= high)


def time_stamp_problem(time: np.ndarray) -> str | None:
    """What is wrong with a grid's time stamps as a whole (not finite, beyond MAX_TIME_STAMP_S), or None."""
    from benchlab.bounds import MAX_TIME_STAMP_S

    if not np.all(np.isfinite(time)):
        return "finite time stamps"
    if len(time) and float(np.max(np.abs(time))) > MAX_TIME_STAMP_S:
        return f"time stamps within ±{MAX_TIME_STAMP_S:g} s, got {float(time[np.argmax(np.abs(time))]):g}"
    return None


def time_step_tolerance(time: np.ndarray, dt: float, stored: np.dtype) -> float:
    """How far a step may differ from dt: a millionth of dt plus the rounding of the stored type."""
    eps = np.finfo(stored).eps if np.issubdtype(stored, np.floating) else 0.0
    return TIME_TOLERANCE * dt + 4 * eps * float(np.max(np.abs(time)))
