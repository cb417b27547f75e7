"""Faults to inject into the simulated bench at a simulated time: each acts on the physics or an emulator.

A `Fault` is data (when, what, how much); `SimBench.service()` applies it once the clock passes `at_s`.
Transport-level faults (corrupted bytes, a muted instrument, a silent controller, a disconnected port) use
the emulators' own hooks, so the drivers see exactly what they would see on hardware. `KINDS` is the one
registry of fault kinds: what each does and which options (Fault fields) it reads; `parse_fault` reads the
command line's `KIND@SECONDS[:key=value,...]` against it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from benchlab.bounds import MAX_RUN_DURATION_S
from drivers.can_signals import CONTROLLERS

SPEC = "KIND@SECONDS[:key=value,...]"


@dataclass(frozen=True)
class Fault:
    """`kind` at `at_s` seconds of run time; `value`/`duration_s`/`target` as the kind needs."""

    at_s: float
    kind: str
    value: float = 0.0
    duration_s: float = 0.0
    target: str = ""

    def apply(self, bench: Any) -> None:
        KINDS[self.kind].apply(bench, self)

    def describe(self) -> str:
        return f"{self.kind} at {self.at_s:g} s (value {self.value:g}, {self.duration_s:g} s, {self.target or '-'})"


def _heater(node: str):
    def apply(bench: Any, f: Fault) -> None:
        bench.physics.set_fault_heat(node, f.value)
    return apply


def _radio_silence(bench: Any, f: Fault) -> None:
    bench.node.radio_silence(f.duration_s)


def _controller_silent(bench: Any, f: Fault) -> None:
    bench.can.silence(f.target or "drive", True)


def _controller_back(bench: Any, f: Fault) -> None:
    bench.can.silence(f.target or "drive", False)


def _controller_frozen(on: bool):
    def apply(bench: Any, f: Fault) -> None:
        bench.can.freeze_alive(f.target or "drive", on)
    return apply


def _controller_fault(bench: Any, f: Fault) -> None:
    bench.can.set_fault(f.target or "load", int(f.value) or 1)


def _controller_fault_cleared(bench: Any, f: Fault) -> None:
    bench.can.clear_fault(f.target or "load")


def _host_stall(bench: Any, f: Fault) -> None:
    bench.clock.sleep_until(bench.clock() + f.duration_s)  # the PC sends nothing meanwhile; the emulators run on


def _stuck_clutch(bench: Any, f: Fault) -> None:
    bench.physics.stick_clutch(f.value, f.duration_s)


def _node_clock_drift(bench: Any, f: Fault) -> None:
    bench.node.clock_drift(f.value)


def _node_clock_jump(bench: Any, f: Fault) -> None:
    bench.node.clock_jump(f.value)


def _corrupt_node(bench: Any, f: Fault) -> None:
    bench.node.corrupt_next("flip", int(f.value) or 1)


def _instrument_error(bench: Any, f: Fault) -> None:
    bench.dmm.inject_error(int(f.value) or -310, f.target or "System error")


def _instrument_mute(on: bool):
    def apply(bench: Any, f: Fault) -> None:
        bench.dmm.mute = on
    return apply


def _instrument_disconnect(bench: Any, f: Fault) -> None:
    bench.dmm.connected = False


def _instrument_reconnect(bench: Any, f: Fault) -> None:
    bench.dmm.connected = True


def _number(low: float, high: float, integer: bool = False) -> Callable[[str], float]:
    """Reads a finite number in [low, high] (an integer if `integer`); ValueError saying what was expected."""
    expected = f"{'an integer' if integer else 'a number'} in [{low:g}, {high:g}]"

    def read(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (low <= value <= high and (not integer or value.is_integer())):
            raise ValueError(f"{expected}, got {text!r}")
        return value
    return read


def _controller(text: str) -> str:
    if text not in CONTROLLERS:
        raise ValueError(f"one of {', '.join(CONTROLLERS)}, got {text!r}")
    return text


def _error_text(text: str) -> str:
    """An instrument error message as SCPI quotes it: printable ASCII without quotes, at most 60 characters."""
    if not (0 < len(text) <= 60 and text.isascii() and text.isprintable() and '"' not in text):
        raise ValueError(f"printable text without quotes, 1-60 characters, got {text!r}")
    return text


@dataclass(frozen=True)
class Option:
    """A key of a fault spec (a Fault field): what it sets, how its text is read (ValueError if bad), required or not."""

    meaning: str
    read: Callable[[str], float | str]
    required: bool = False


@dataclass(frozen=True)
class FaultKind:
    """What a kind of fault does to the simulated bench, and the options (Fault fields) it reads."""

    apply: Callable[[Any, Fault], None]
    about: str
    options: Mapping[str, Option] = field(default_factory=dict)


_DURATION = Option("s it lasts", _number(1e-3, MAX_RUN_DURATION_S), required=True)
_HEAT = Option("W (0 switches it off)", _number(0.0, 1e6))


def _target(default: str) -> Mapping[str, Option]:
    return {"target": Option(f"controller ({', '.join(CONTROLLERS)}; default {default})", _controller)}


KINDS: dict[str, FaultKind] = {
    "flywheel_heater": FaultKind(_heater("F"), "heat into the flywheel: over-temperature", {"value": _HEAT}),
    "air_heater": FaultKind(_heater("A"), "heat into the chamber air", {"value": _HEAT}),
    "radio_silence": FaultKind(_radio_silence, "the node's frames are lost", {"duration_s": _DURATION}),
    "controller_silent": FaultKind(_controller_silent, "a controller stops sending (heartbeat lost)",
                                   _target("drive")),
    "controller_back": FaultKind(_controller_back, "a silent controller sends again", _target("drive")),
    "controller_frozen": FaultKind(_controller_frozen(True), "a controller's task hangs: its alive counters stop, its "
                                   "last values repeat", _target("drive")),
    "controller_unfrozen": FaultKind(_controller_frozen(False), "a hung controller counts again", _target("drive")),
    "controller_fault": FaultKind(_controller_fault, "a controller reports a fault code", {
        "value": Option("fault code (default 1)", _number(1, 255, integer=True)), **_target("load")}),
    "controller_fault_cleared": FaultKind(_controller_fault_cleared, "a controller's fault clears", _target("load")),
    "host_stall": FaultKind(_host_stall, "the PC stalls: no command, no read for duration_s (the controllers' own "
                            "command time-out must make them safe)", {"duration_s": _DURATION}),
    "stuck_clutch": FaultKind(_stuck_clutch, "clutch clamped and output braked, whatever is commanded", {
        "value": Option("N*m the clutch holds", _number(0.0, 1e4), required=True), "duration_s": _DURATION}),
    "node_clock_drift": FaultKind(_node_clock_drift, "the node's clock runs fast (slow: negative) from now on", {
        "value": Option("ppm (-5000: 0.5 % slow)", _number(-1e5, 1e5), required=True)}),
    "node_clock_jump": FaultKind(_node_clock_jump, "the node's clock jumps (no reboot)", {
        "value": Option("s (negative: back)", _number(-1e4, 1e4), required=True)}),
    "corrupt_node_frames": FaultKind(_corrupt_node, "the next node frames arrive with a flipped bit (CRC errors)", {
        "value": Option("frames (default 1)", _number(1, 1e5, integer=True))}),
    "instrument_error": FaultKind(_instrument_error, "an entry in the scanner's SCPI error queue", {
        "value": Option("SCPI error code (default -310)", _number(-999, 999, integer=True)),
        "target": Option("error text (default System error)", _error_text)}),
    "instrument_mute": FaultKind(_instrument_mute(True), "the scanner takes commands but never answers (time-outs)"),
    "instrument_unmute": FaultKind(_instrument_mute(False), "the scanner answers again"),
    "instrument_disconnect": FaultKind(_instrument_disconnect, "the scanner's port is unplugged"),
    "instrument_reconnect": FaultKind(_instrument_reconnect, "the scanner's port is plugged in again"),
}


def kinds_help() -> str:
    """The kinds and their keys in one line, for --help: kind(key,key) ..."""
    return ", ".join(f"{name}({','.join(kind.options)})" if kind.options else name for name, kind in KINDS.items())


def parse_fault(spec: str) -> Fault:
    """A Fault from `KIND@SECONDS[:key=value,...]`, checked against `KINDS` (a time within the longest run,
    benchlab.bounds); ValueError saying what is wrong."""
    head, _, options = spec.partition(":")
    name, at, seconds = head.partition("@")
    kind = KINDS.get(name)
    if kind is None:
        raise ValueError(f"unknown fault kind {name!r} (one of {', '.join(KINDS)})")
    try:
        at_s = float(seconds) if at else math.nan
    except ValueError:
        at_s = math.nan
    if not 0 <= at_s <= MAX_RUN_DURATION_S:
        raise ValueError(f"a time in [0, {MAX_RUN_DURATION_S:g}] s after '@', got {seconds!r}" if at
                         else f"{SPEC}, no '@SECONDS'")
    values: dict[str, Any] = {}
    for item in options.split(",") if options else ():
        key, eq, text = item.partition("=")
        option = kind.options.get(key)
        if option is None:
            raise ValueError(f"{name} takes {', '.join(kind.options) or 'no keys'}, got {key!r}")
        if not eq or key in values:
            raise ValueError(f"each key once as key=value, got {item!r}")
        try:
            values[key] = option.read(text)
        except ValueError as exc:
            raise ValueError(f"{name} {key}, {option.meaning}: {exc}") from None
    missing = [key for key, option in kind.options.items() if option.required and key not in values]
    if missing:
        raise ValueError(f"{name} needs {', '.join(f'{k}=' for k in missing)}")
    return Fault(at_s, name, **values)
