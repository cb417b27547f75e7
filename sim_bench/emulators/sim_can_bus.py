"""In-process CAN bus for simulated time: python-can's virtual interface without the per-frame copy and locks.

A `can.BusABC`, so drivers cannot tell it from real hardware. Every bus on the same channel name receives the
frames the others send (the same Message object or frame array: receivers must not modify frames). Like a
hardware interface it stamps each frame: a frame sent without a time stamp gets the channel's clock (the
simulated clock when one is given, else `time.monotonic`; python-can's default stamp 0.0 counts as none); a
frame sent with one (an emulated controller back-dating a frame to the instant it fell due) keeps it.

Besides python-can's `send`/`recv` of one `can.Message`, it carries frames in bulk as FRAME records
(drivers/can_frames.py): `send_frames()` (the emulated controllers' status frames of a poll) and
`recv_frames()` (everything waiting, which `drivers.can_frames.drain` takes); a frame sent one way is received
either way, in the order sent. Tests may use python-can's `virtual` interface instead; this one exists because
the simulated bench must run hundreds of times faster than real time.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

import can
import numpy as np
from benchlab.jit import njit

from drivers.can_frames import FRAME, frames_from_messages, join, messages_from_frames, recv_each

_channels: dict[str, list["SimCanBus"]] = {}
_clocks: dict[str, Callable[[], float]] = {}
_WAIT_S = 0.0005


class SimCanBus(can.BusABC):
    """One node's connection to the in-process channel `channel`; `clock` (shared by the channel) stamps frames."""

    def __init__(self, channel: str = "sim", *, clock: Callable[[], float] | None = None,
                 receive_own_messages: bool = False, **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"sim-can {channel}"
        self.receive_own_messages = receive_own_messages
        self._queue: deque[can.Message | np.ndarray] = deque()
        self._head = 0  # frames of the first queued array already received one by one
        self._peers = _channels.setdefault(channel, [])
        self._peers.append(self)
        if clock is not None:
            _clocks[channel] = clock
        self._channel = channel

    def _now(self) -> float:
        return _clocks.get(self._channel, time.monotonic)()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not msg.timestamp:
            msg.timestamp = self._now()
        self._deliver(msg)

    def send_frames(self, frames: np.ndarray) -> None:
        """Put FRAME records on the bus in their order (unstamped ones get the channel's clock)."""
        if not len(frames):
            return
        if _any_unstamped(frames):
            frames = frames.copy()
            stamps = frames["timestamp"]
            stamps[stamps == 0] = self._now()
        shared = frames.view()  # every peer queues the same frames, read-only (the sender's array stays as it was)
        shared.flags.writeable = False
        self._deliver(shared)

    def _deliver(self, item: "can.Message | np.ndarray") -> None:
        for bus in self._peers:
            if bus is not self or self.receive_own_messages:
                bus._queue.append(item)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """Next frame; with a timeout, wait for one in wall-clock time (filters honoured via python-can)."""
        if self._filters:
            return super().recv(timeout)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            msg = self._next()
            if msg is not None or timeout == 0 or (deadline is not None and time.monotonic() >= deadline):
                return msg
            time.sleep(_WAIT_S)

    def recv_frames(self) -> np.ndarray:
        """Every waiting frame as FRAME records, in the order sent."""
        if self._filters:
            return recv_each(self)
        parts, messages = [], []
        while self._queue:
            item = self._queue.popleft()
            if isinstance(item, can.Message):
                messages.append(item)
                continue
            if messages:
                parts.append(frames_from_messages(messages))
                messages = []
            parts.append(item[self._head:])
            self._head = 0
        if messages:
            parts.append(frames_from_messages(messages))
        frames = join(parts)  # the receiver's own writable array, as a hardware bus hands out (one type for its
        return frames if frames.flags.writeable else frames.copy()  # compiled passes, however many parts)

    def _next(self) -> can.Message | None:
        if not self._queue:
            return None
        item = self._queue[0]
        if isinstance(item, can.Message):
            return self._queue.popleft()
        (msg,) = messages_from_frames(item[self._head:self._head + 1])
        self._head += 1
        if self._head == len(item):
            self._queue.popleft()
            self._head = 0
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self._next(), False

    def shutdown(self) -> None:
        if self in self._peers:
            self._peers.remove(self)
        if not self._peers:
            _channels.pop(self._channel, None)
            _clocks.pop(self._channel, None)
        super().shutdown()



@njit(cache=True, nogil=True)
def _any_unstamped(frames: np.ndarray) -> bool:  # pragma: no cover - compiled
    """Whether any FRAME record has time stamp 0 (none given): one compiled pass, no temporary arrays."""
    for i in range(frames.shape[0]):
        if frames[i].timestamp == 0:
            return True
    return False


def prime() -> None:
    """Compile (or load from numba's cache) the bus's kernel before a real-time run, on zero frames."""
    _any_unstamped(np.zeros(0, FRAME))
