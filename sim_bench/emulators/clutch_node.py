"""Emulated ClutchSensorNode + PC node: one frame (drivers/NODE_FRAME.md) per period on a serial endpoint.

Frames are produced lazily for every period that elapsed on the injected clock when the host reads, so it
runs in simulated time at any speed. Fault hooks: `radio_silence`, `power_loss`, `restart`,
`corrupt_next`, `inject_bytes`, `connected = False`; open/short sensors come from the provider
(inf/NaN → open, below 150 Ω → short), a low supply sets LOW_SUPPLY.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Literal

from drivers import cobs, node_frame
from drivers.node_frame import NodeFrame
from sim_bench.emulators.providers import ConstantNodeInputs, NodeInputProvider, NodeInputs

Damage = Literal["flip", "truncate", "garbage"]
_OPEN = (node_frame.CH1_OPEN, node_frame.CH2_OPEN)
_SHORT = (node_frame.CH1_SHORT, node_frame.CH2_SHORT)


class ClutchNodeEmulator:
    """Serial endpoint producing node frames from `provider.node_inputs_at(times)` every `period_s` of clock time."""

    def __init__(self, provider: NodeInputProvider | None = None, *, period_s: float = 0.05,
                 clock: Callable[[], float] = time.monotonic, short_ohm: float = 150.0,
                 low_supply_mv: int = 3600) -> None:
        self.provider = provider or ConstantNodeInputs()
        self.period_s, self.clock = period_s, clock
        self.short_ohm, self.low_supply_mv = short_ohm, low_supply_mv
        self.connected = True
        self.frames_sent = 0
        self.frames_suppressed = 0
        self._next_t = clock()
        self._boot(self._next_t)
        self._silent_until = -math.inf
        self._off_until = -math.inf
        self._damage: list[Damage] = []
        self._out = bytearray()

    # -- serial endpoint -----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        """The PC node has no downlink; bytes from the host are ignored."""

    def read_available(self) -> bytes:
        """Bytes of every frame due up to the clock's current time."""
        now = self.clock()
        due = []
        while self._next_t <= now:
            if self._next_t >= self._off_until:  # powered: the node measures and sends
                due.append(self._next_t)
            self._next_t += self.period_s
        if due:
            frames: list[NodeFrame] = []  # undamaged frames not yet on the line, encoded together
            for t, inputs in zip(due, self.provider.node_inputs_at(due)):
                self._emit(t, inputs, frames)
            self._out += node_frame.encode_many(frames)
        data, self._out = bytes(self._out), bytearray()
        return data

    # -- fault hooks ---------------------------------------------------------------------------------
    def radio_silence(self, duration_s: float) -> None:
        """Frames sent in the next `duration_s` are lost on the radio (the node keeps counting)."""
        self._silent_until = self.clock() + duration_s

    def power_loss(self, duration_s: float) -> None:
        """The inductive supply fails for `duration_s`: no frames, then the node reboots."""
        now = self.clock()
        self._off_until = now + duration_s
        self._boot(now + duration_s)

    def restart(self) -> None:
        """The node reboots now: seq 0, node clock 0, NODE_RESET on the first frame."""
        self._boot(self.clock())

    def corrupt_next(self, how: Damage = "flip", count: int = 1) -> None:
        """Damage the next `count` frames: flip one bit, cut off the tail, or replace bytes with garbage."""
        self._damage += [how] * count

    def inject_bytes(self, data: bytes) -> None:
        """Put raw bytes (noise) on the line before the next frame."""
        self._out += data

    # -- internals -------------------------------------------------------------------------------------
    def _boot(self, t: float) -> None:
        self._t_boot, self._seq, self._reset_flag = t, 0, node_frame.NODE_RESET

    def _emit(self, t: float, inputs: NodeInputs, pending: list[NodeFrame]) -> None:
        """The frame measured at `t` onto the line, after the undamaged ones `pending` (kept there if undamaged)."""
        frame = self._frame(t, inputs)
        self._seq = (self._seq + 1) & 0xFFFF
        self._reset_flag = 0
        if t < self._silent_until:
            self.frames_suppressed += 1
            return
        self.frames_sent += 1
        if not self._damage:
            pending.append(frame)
            return
        self._out += node_frame.encode_many(pending) + self._wire(frame, self._damage.pop(0))
        pending.clear()

    def _frame(self, t: float, inputs: NodeInputs) -> NodeFrame:
        flags = self._reset_flag | (node_frame.LOW_SUPPLY if inputs.supply_mv < self.low_supply_mv else 0)
        raw = []
        for ch, ohm in enumerate(inputs.resistances_ohm):
            if not math.isfinite(ohm):
                flags |= _OPEN[ch]
                raw.append(node_frame.NO_VALUE)
            elif ohm < self.short_ohm:
                flags |= _SHORT[ch]
                raw.append(node_frame.NO_VALUE)
            else:
                raw.append(min(round(ohm * 1000), node_frame.NO_VALUE - 1))
        node_ms = int(round((t - self._t_boot) * 1000)) & 0xFFFFFFFF
        return NodeFrame(self._seq, node_ms, (raw[0], raw[1]), max(0, min(inputs.supply_mv, 0xFFFF)),
                         max(-128, min(inputs.rssi_dbm, 127)), max(0, min(inputs.lqi, 255)), flags)

    @staticmethod
    def _wire(frame: NodeFrame, damage: Damage) -> bytes:
        """Encoded frame, damaged on request: a bit flipped in the payload (CRC catches it), cut off, or garbled."""
        if damage == "flip":
            payload = bytearray(node_frame.pack(frame))
            payload[len(payload) // 2] ^= 0x01
            return cobs.encode(bytes(payload)) + node_frame.DELIMITER
        wire = node_frame.encode(frame)
        if damage == "truncate":
            return wire[: len(wire) // 2] + node_frame.DELIMITER
        if damage == "garbage":
            return b"\x5a\xa5\xff\x13" + wire[4:]
        return wire
