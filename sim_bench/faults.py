"""Faults to inject into the simulated bench at a simulated time: each acts on the physics or an emulator.

A `Fault` is data (when, what, how much); `SimBench.service()` applies it once the clock passes `at_s`.
Transport-level faults (corrupted bytes, a muted instrument, a silent controller, a disconnected port) use
the emulators' own hooks, so the drivers see exactly what they would see on hardware.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Fault:
    """`kind` at `at_s` seconds of run time; `value`/`duration_s`/`target` as the kind needs."""

    at_s: float
    kind: str
    value: float = 0.0
    duration_s: float = 0.0
    target: str = ""

    def apply(self, bench: Any) -> None:
        KINDS[self.kind](bench, self)

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


def _controller_fault(bench: Any, f: Fault) -> None:
    bench.can.set_fault(f.target or "load", int(f.value) or 1)


def _controller_fault_cleared(bench: Any, f: Fault) -> None:
    bench.can.clear_fault(f.target or "load")


def _stuck_clutch(bench: Any, f: Fault) -> None:
    bench.physics.stick_clutch(f.value, f.duration_s)


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


KINDS = {
    "flywheel_heater": _heater("F"),  # W into the flywheel (0 switches it off): over-temperature
    "air_heater": _heater("A"),  # W into the chamber air
    "radio_silence": _radio_silence,  # the node's frames are lost for duration_s
    "controller_silent": _controller_silent,  # target controller stops sending (heartbeat lost)
    "controller_back": _controller_back,
    "controller_fault": _controller_fault,  # target controller reports fault code `value`
    "controller_fault_cleared": _controller_fault_cleared,
    "stuck_clutch": _stuck_clutch,  # clutch clamped at `value` N*m and output braked for duration_s
    "corrupt_node_frames": _corrupt_node,
    "instrument_error": _instrument_error,
    "instrument_mute": _instrument_mute(True),  # the scanner takes commands but never answers (time-outs)
    "instrument_unmute": _instrument_mute(False),
    "instrument_disconnect": _instrument_disconnect,  # the port is gone (a pulled USB adapter)
    "instrument_reconnect": _instrument_reconnect,
}
