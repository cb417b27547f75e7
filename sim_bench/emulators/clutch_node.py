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

import numpy as np
from benchlab.jit import njit

from drivers import cobs, node_frame
from drivers.node_frame import NodeFrame
from sim_bench.emulators.providers import ConstantNodeInputs, NodeInputProvider, NodeInputSeries

Damage = Literal["flip", "truncate", "garbage"]
_OPEN = (node_frame.CH1_OPEN, node_frame.CH2_OPEN)
_SHORT = (node_frame.CH1_SHORT, node_frame.CH2_SHORT)
SHORT_OHM, LOW_SUPPLY_MV = 150.0, 3600  # the emulator's defaults: a sensor below this is short, a supply low


class ClutchNodeEmulator:
    """Serial endpoint producing node frames from `provider.node_inputs_at(times)` every `period_s` of clock time."""

    def __init__(self, provider: NodeInputProvider | None = None, *, period_s: float = 0.05,
                 clock: Callable[[], float] = time.monotonic, short_ohm: float = SHORT_OHM,
                 low_supply_mv: int = LOW_SUPPLY_MV) -> None:
        self.provider = provider or ConstantNodeInputs()
        self.period_s, self.clock = period_s, clock
        self.short_ohm, self.low_supply_mv = short_ohm, low_supply_mv
        self.connected = True
        self.frames_sent = 0
        self.frames_suppressed = 0
        self._next_t = clock()
        self._rate = 1.0  # node clock s per s of clock time (a crystal off by some ppm)
        self._boot(self._next_t)
        self._silent_until = -math.inf
        self._off_until = -math.inf
        self._damage: list[Damage] = []
        self._out = bytearray()  # bytes on the line not yet read: injected noise, damaged frames
        self._link_key: tuple[int, int, int] | None = None  # constant supply, RSSI, LQI and their row for the kernel
        self._link = np.zeros((1, 3), dtype=np.int64)

    # -- serial endpoint -----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        """The PC node has no downlink; bytes from the host are ignored."""

    def read_available(self) -> bytes:
        """Bytes of every frame due up to the clock's current time."""
        now = self.clock()
        if self._next_t > now and not self._out:
            return b""
        due = []
        while self._next_t <= now:
            if self._next_t >= self._off_until:  # powered: the node measures and sends
                due.append(self._next_t)
            self._next_t += self.period_s
        frames = self._emit(np.array(due)) if due else b""
        if not self._out:
            return frames
        data, self._out = bytes(self._out) + frames, bytearray()
        return data

    # -- fault hooks ---------------------------------------------------------------------------------
    def radio_silence(self, duration_s: float) -> None:
        """Frames sent in the next `duration_s` are lost on the radio (the node keeps counting). A silence extends
        one under way, never shortens it: a short random drop-out during a rehearsed 30 s silence ends nothing."""
        self._silent_until = max(self._silent_until, self.clock() + duration_s)

    def power_loss(self, duration_s: float) -> None:
        """The inductive supply fails for `duration_s`: no frames, then the node reboots (a loss during one under
        way extends it, never shortens it)."""
        self._off_until = max(self._off_until, self.clock() + duration_s)
        self._boot(self._off_until)

    def restart(self) -> None:
        """The node reboots now: seq 0, node clock 0, NODE_RESET on the first frame."""
        self._boot(self.clock())

    def clock_drift(self, ppm: float) -> None:
        """From now on the node's clock runs `ppm` parts per million fast (negative: slow)."""
        self._clock_anchor = (self.clock(), self._node_time(self.clock()))
        self._rate = 1.0 + ppm * 1e-6

    def clock_jump(self, seconds: float) -> None:
        """The node's clock jumps by `seconds` now (forward or back; seq goes on: no reboot)."""
        now = self.clock()
        self._clock_anchor = (now, self._node_time(now) + seconds)

    def corrupt_next(self, how: Damage = "flip", count: int = 1) -> None:
        """Damage the next `count` frames: flip one bit, cut off the tail, or replace bytes with garbage."""
        self._damage += [how] * count

    def inject_bytes(self, data: bytes) -> None:
        """Put raw bytes (noise) on the line before the next frame."""
        self._out += data

    # -- internals -------------------------------------------------------------------------------------
    def _boot(self, t: float) -> None:
        self._t_boot, self._seq, self._reset_flag = t, 0, node_frame.NODE_RESET
        self._clock_anchor = (t, t)  # (clock time, node time on the clock's scale) the node clock runs from

    def _node_time(self, times: "float | np.ndarray") -> "float | np.ndarray":
        """The node clock at clock times `times`, on the clock's scale (its ms field counts from `_t_boot`)."""
        t0, node0 = self._clock_anchor
        return node0 + (times - t0) * self._rate

    def _emit(self, times: np.ndarray) -> bytes:
        """The frames measured at `times`: those in a radio silence are lost, the next ones damaged on request (onto
        the line at once), the rest encoded together and returned."""
        inputs = self.provider.node_inputs_at(times)
        n = len(times)
        # a fresh C-contiguous writable copy: the provider's view (read-only, strided) would be a second signature
        # of the compiled kernels, compiled at the first frame in a real-time run instead of by prime()
        ohm, link = np.array(inputs.resistances_ohm, dtype=float, order="C"), self._link_rows(inputs, n)
        args = (self._node_time(times), ohm, link, self._t_boot, self._seq, self._reset_flag, self.short_ohm,
                self.low_supply_mv)
        self._seq = (self._seq + n) & 0xFFFF
        self._reset_flag = 0
        if times[0] >= self._silent_until and not self._damage:  # the usual read: every frame sent intact
            self.frames_sent += n
            return _frame_wire(*args).tobytes()
        fields = _frame_fields(*args)
        if times[0] < self._silent_until:
            sent = times >= self._silent_until
            self.frames_suppressed += n - int(np.count_nonzero(sent))
            fields = fields[sent]
        self.frames_sent += len(fields)
        damaged = min(len(self._damage), len(fields))
        for row in fields[:damaged].tolist():
            self._out += self._wire(node_frame.frame_of(row), self._damage.pop(0))
        return node_frame.encode_rows(fields[damaged:])

    def _link_rows(self, inputs: NodeInputSeries, n: int) -> np.ndarray:
        """Supply, RSSI and LQI as rows (n, 3) for the kernel, or one row (1, 3) if each is one value for all."""
        key = supply, rssi, lqi = inputs.supply_mv, inputs.rssi_dbm, inputs.lqi
        if type(supply) is int and type(rssi) is int and type(lqi) is int:
            if key != self._link_key:
                self._link_key, self._link = key, np.array([key], dtype=np.int64)
            return self._link
        return np.column_stack([np.broadcast_to(np.asarray(v, dtype=np.int64).reshape(-1), n) for v in key])

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


@njit(cache=True, nogil=True)
def _frame_fields(times: np.ndarray, ohm: np.ndarray, link: np.ndarray, t_boot: float, seq: int, reset_flag: int,
                  short_ohm: float,
                  low_supply_mv: int) -> np.ndarray:  # pragma: no cover - compiled
    """Rows (node_frame.FIELDS order) of the frames measured at `times`, the first with sequence number `seq` and
    `reset_flag` (`link`: supply, RSSI and LQI, one row per frame or one for all): open (inf/NaN) and short (below `short_ohm`) sensors flagged with NO_VALUE, a low supply flagged,
    the node clock in ms since `t_boot`, every field clamped to its width."""
    out = np.empty((times.shape[0], 9), dtype=np.int64)
    for i in range(times.shape[0]):
        flags = reset_flag if i == 0 else 0
        k = i if link.shape[0] > 1 else 0
        supply, rssi, lqi_i = link[k, 0], link[k, 1], link[k, 2]
        if supply < low_supply_mv:
            flags |= node_frame.LOW_SUPPLY
        for ch in range(2):
            r = ohm[i, ch]
            if not np.isfinite(r):
                flags |= _OPEN[ch]
                out[i, 4 + ch] = node_frame.NO_VALUE
            elif r < short_ohm:
                flags |= _SHORT[ch]
                out[i, 4 + ch] = node_frame.NO_VALUE
            else:
                out[i, 4 + ch] = np.int64(min(np.rint(r * 1000.0), float(node_frame.NO_VALUE - 1)))  # min of two floats
        out[i, 0], out[i, 1], out[i, 2] = node_frame.VERSION, flags, (seq + i) & 0xFFFF
        out[i, 3] = np.int64(np.rint((times[i] - t_boot) * 1000.0)) & 0xFFFFFFFF
        out[i, 6] = max(0, min(supply, 0xFFFF))
        out[i, 7] = max(-128, min(rssi, 127))
        out[i, 8] = max(0, min(lqi_i, 255))
    return out


@njit(cache=True, nogil=True)
def _frame_wire(times: np.ndarray, ohm: np.ndarray, link: np.ndarray, t_boot: float, seq: int, reset_flag: int,
                short_ohm: float, low_supply_mv: int) -> np.ndarray:  # pragma: no cover - compiled
    """The wire bytes of `_frame_fields`'s frames (node_frame.encode_rows) in the same compiled call."""
    return node_frame.wire_of_rows(_frame_fields(times, ohm, link, t_boot, seq, reset_flag, short_ohm, low_supply_mv))


def prime() -> None:
    """Compile (or load from numba's cache) the node emulator's kernels before a real-time run, for the one
    signature each is called with: no frame times, one constant link row, the emulator's default limits."""
    times, ohm, link = np.zeros(0), np.zeros((0, 2)), np.zeros((1, 3), np.int64)
    _frame_fields(times, ohm, link, 0.0, 0, node_frame.NODE_RESET, SHORT_OHM, LOW_SUPPLY_MV)
    _frame_wire(times, ohm, link, 0.0, 0, node_frame.NODE_RESET, SHORT_OHM, LOW_SUPPLY_MV)
