"""BENCH.toml: where a hardware bench's devices are, how its channels map, its calibration and limits.

Every field is checked before anything is opened; a bad one raises InputError naming it (one line, exit 2).
See examples/bench.toml.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import cantools

from benchlab.bounds import BENCH_NUMBER_RANGES
from benchlab.drivetrain import DrivetrainFacts
from benchlab.errors import InputError, read_document
from benchlab.runner.devices import BenchConfig, duplicate_message, load_dbc, status_cycle_s
from benchlab.runner.opening import check_address
from benchlab.values import check_keys, finite_number, positive_number
from drivers import cvd
from drivers.can_signals import BENCH_DBC, BENCH_SIGNALS
from protocols.limits import BenchLimits

ALIGNED_TEMPERATURES = ("T_air", "T_housing", "T_ambient", "T_engine")
_SECTIONS = ("instrument", "node", "can", "drivetrain", "acquisition", "limits")
ACQUISITION_KEYS = ("dt", "tick_s", "fast_tick_s", "flush_every_s")  # [acquisition]; defaults: BenchConfig's
# The keys of [instrument] and [node]; [can] is python-can's (passed to can.Bus) and takes any key.
INSTRUMENT_KEYS = ("url", "channels", "mode", "calibration", "baudrate", "timeout_s", "period_s")
NODE_KEYS = ("url", "calibration", "baudrate", "period_s")
CVD_KEYS = ("r0", "a", "b", "c")


def _table(doc: Mapping[str, Any], key: str, src: str, required: bool = True) -> Mapping[str, Any]:
    value = doc.get(key)
    if value is None and not required:
        return {}
    if not isinstance(value, dict):
        raise InputError(src, key, "a table" + (" (missing)" if value is None else f", got {value!r}"))
    return value


def _str(t: Mapping[str, Any], key: str, field: str, src: str, default: str | None = None) -> str:
    value = t.get(key, default)
    if not isinstance(value, str) or not value:
        raise InputError(src, field, f"a non-empty string, got {value!r}")
    return value


def _num(t: Mapping[str, Any], key: str, field: str, src: str, default: float, integer: bool = False) -> float:
    """A number of BENCH.toml within its physical range (benchlab.bounds.BENCH_NUMBER_RANGES)."""
    value = t.get(key, default)
    if positive_number(value) is None:
        raise InputError(src, field, f"a positive number, got {value!r}")
    low, high = BENCH_NUMBER_RANGES[field]
    if not low <= value <= high:
        raise InputError(src, field, f"{'at least' if value < low else 'at most'} {low if value < low else high:g} "
                                     f"(from {low:g} to {high:g}), got {value!r}")
    if integer and int(value) != value:
        raise InputError(src, field, f"an integer, got {value!r}")
    return int(value) if integer else float(value)


def _coefficients(t: Any, field: str, src: str) -> cvd.CvdCoefficients:
    if not isinstance(t, dict):
        raise InputError(src, field, f"a table of Callendar-Van Dusen coefficients r0, a, b, c, got {t!r}")
    check_keys(src, field, t, CVD_KEYS)
    values = {}
    for key in t:
        number = finite_number(t[key])
        if number is None:
            raise InputError(src, f"{field}.{key}", f"a finite number, got {t[key]!r}")
        values[key] = number
    if values.get("r0", 1000.0) <= 0:
        raise InputError(src, f"{field}.r0", "a positive resistance in ohm")
    return cvd.CvdCoefficients(**values)


def _is_file(path: Path) -> bool:
    """Whether `path` is a file; a name the system cannot even look up (too long, a NUL byte) is not."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _check_dbc(dbc_path: Path, src: str) -> Any:
    """The DBC loads with cantools and defines every message and signal the CAN driver uses (BENCH_SIGNALS);
    the database."""
    try:
        db = cantools.database.load_file(str(dbc_path))
    except (cantools.database.Error, ValueError, OSError, UnicodeDecodeError) as exc:
        detail = (str(exc).splitlines() or [""])[0][:120].encode("ascii", "backslashreplace").decode()
        raise InputError(src, "can.dbc", f"a DBC file cantools can load ({dbc_path}: {detail})") from None
    if (twice := duplicate_message(db)) is not None:
        raise InputError(src, "can.dbc", f"a DBC defining each message once ({dbc_path} has the {twice})")
    names = {m.name: {s.name for s in m.signals} for m in db.messages}
    for message, signal in BENCH_SIGNALS.values():
        if signal not in names.get(message, ()):
            raise InputError(src, "can.dbc", f"a DBC defining {message}.{signal} like drivers/bench.dbc "
                                             f"({dbc_path} has no such {'signal' if message in names else 'message'})")
    return db


def _setpoint_max(db: Any) -> dict[str, float]:
    """Per set-point key the largest value its DBC signal carries (its maximum, else what its bits hold)."""
    out = {}
    for key in ("drive.speed_setpoint", "clutch.torque_setpoint", "load.torque_setpoint"):
        message, name = BENCH_SIGNALS[key]
        signal = db.get_message_by_name(message).get_signal_by_name(name)
        bits_max = ((1 << (signal.length - signal.is_signed)) - 1) * signal.scale + signal.offset
        out[key] = float(signal.maximum if signal.maximum is not None else bits_max)
    return out


def load_bench_config(path: "str | os.PathLike[str]") -> BenchConfig:
    """Read and check BENCH.toml; InputError naming the first bad field."""
    src = str(path)
    doc = read_document(path, "bench file", tomllib.loads, (tomllib.TOMLDecodeError,), "TOML")
    check_keys(src, "", doc, _SECTIONS)
    inst = _table(doc, "instrument", src)
    check_keys(src, "instrument", inst, INSTRUMENT_KEYS)
    channels_t = _table(inst, "channels", src)
    channels: dict[int, str] = {}
    for key, name in channels_t.items():
        if not (key.isascii() and key.isdigit()) or not 101 <= int(key) <= 999:
            raise InputError(src, f"instrument.channels.{key}", "a channel number like 101")
        if name not in ALIGNED_TEMPERATURES:
            raise InputError(src, f"instrument.channels.{key}", f"one of {', '.join(ALIGNED_TEMPERATURES)}, got {name!r}")
        channels[int(key)] = name
    for required in ("T_air", "T_housing", "T_ambient"):
        if required not in channels.values():
            raise InputError(src, "instrument.channels", f"a channel for {required} (missing)")
    mode = inst.get("mode", "fres")
    if mode not in ("fres", "frtd"):
        raise InputError(src, "instrument.mode", f"fres or frtd, got {mode!r}")
    calib_t = _table(inst, "calibration", src, required=False)
    calibration = {}
    for key, coef in calib_t.items():
        if not (key.isascii() and key.isdigit()) or int(key) not in channels:
            raise InputError(src, f"instrument.calibration.{key}", "a configured channel number")
        calibration[int(key)] = _coefficients(coef, f"instrument.calibration.{key}", src)
    node = _table(doc, "node", src)
    check_keys(src, "node", node, NODE_KEYS)
    node_cal = _table(node, "calibration", src, required=False)
    node_coefs = []
    for i in (1, 2):
        node_coefs.append(_coefficients(node_cal[str(i)], f"node.calibration.{i}", src) if str(i) in node_cal
                          else cvd.PT1000)
    for key in node_cal:
        if key not in ("1", "2"):
            raise InputError(src, f"node.calibration.{key}", "1 or 2 (the flywheel sensors)")
    can_t = _table(doc, "can", src)
    if "url" in can_t:  # the simulated plant's emulated controllers instead of a python-can bus
        url = _str(can_t, "url", "can.url", src)
        if not url.startswith("sim://") or len(url) == len("sim://"):
            raise InputError(src, "can.url", f"sim://NAME (the emulated controllers), got {url!r}; hardware is "
                                              "given by python-can's keys (interface, channel, bitrate)")
        check_keys(src, "can", can_t, ("url", "dbc"))
    else:
        interface = _str(can_t, "interface", "can.interface", src)
        if interface == "udp_multicast":
            raise InputError(src, "can.interface", "a CAN interface; udp_multicast leaves the machine, not allowed")
    can_cfg = {k: v for k, v in can_t.items() if k != "dbc"}
    dbc = can_t.get("dbc")
    if dbc is not None:
        dbc_path = Path(path).parent / _str(can_t, "dbc", "can.dbc", src)
        if not _is_file(dbc_path):
            raise InputError(src, "can.dbc", f"an existing DBC file ({dbc_path} not found)")
        db = _check_dbc(dbc_path, src)
        dbc = str(dbc_path)
    else:
        db = load_dbc(str(BENCH_DBC))
    drive = _table(doc, "drivetrain", src, required=False)
    acq = _table(doc, "acquisition", src, required=False)
    check_keys(src, "acquisition", acq, ACQUISITION_KEYS)
    limits = BenchLimits.from_mapping(_table(doc, "limits", src, required=False), src)
    limits.check_physics(src, _setpoint_max(db))
    check_keys(src, "drivetrain", drive, DrivetrainFacts.__dataclass_fields__)
    drivetrain = DrivetrainFacts(*(_num(drive, key, f"drivetrain.{key}", src, getattr(DrivetrainFacts, key))
                                   for key in DrivetrainFacts.__dataclass_fields__))
    config = BenchConfig(
        instrument_url=check_address(_str(inst, "url", "instrument.url", src), source=src, key="instrument.url"),
        node_url=check_address(_str(node, "url", "node.url", src), source=src, key="node.url"),
        can=can_cfg, instrument_channels=channels, instrument_mode=mode,
        instrument_baudrate=int(_num(inst, "baudrate", "instrument.baudrate", src, 115200, True)),
        instrument_timeout_s=_num(inst, "timeout_s", "instrument.timeout_s", src, 2.0),
        instrument_period_s=_num(inst, "period_s", "instrument.period_s", src, 0.2),
        instrument_calibration=calibration,
        node_baudrate=int(_num(node, "baudrate", "node.baudrate", src, 921600, True)),
        node_period_s=_num(node, "period_s", "node.period_s", src, 0.05),
        node_calibration=(node_coefs[0], node_coefs[1]), dbc=dbc,
        drivetrain=drivetrain,
        **{key: _num(acq, key, f"acquisition.{key}", src, getattr(BenchConfig, key))
           for key in ACQUISITION_KEYS},
        limits=replace(limits, drivetrain=drivetrain), source=src)
    _check_ages(config, src)
    return config


def _check_ages(config: BenchConfig, src: str) -> None:
    """Each `[limits.max_age_s]` longer than its source's own gaps: two of its periods (the DBC's cycle for the CAN
    channels) and, for T_air, one scanner time-out; a shorter age trips its interlock on a healthy bench."""
    cycles = {"engine_speed": "drive.speed", "clutch_speed": "load.speed", "clutch_torque": "clutch.torque"}
    shortest = {"T_air": max(2 * config.instrument_period_s, config.instrument_timeout_s),
                "T_flywheel": 2 * config.node_period_s,
                **{channel: 2 * status_cycle_s(config, key) for channel, key in cycles.items()}}
    for channel, age in config.limits.max_age_s.items():
        if not age > shortest[channel]:
            why = "two periods of its source" + (", one scanner time-out" if channel == "T_air" else "")
            raise InputError(src, f"limits.max_age_s.{channel}", f"more than {shortest[channel]:g} s ({why}), "
                                                                 f"got {age!r}")
