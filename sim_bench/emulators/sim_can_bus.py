"""In-process CAN bus for simulated time: python-can's virtual interface without the per-frame copy and locks.

A `can.BusABC`, so drivers cannot tell it from real hardware. Every bus on the same channel name receives the
frames the others send (the same Message object: receivers must not modify frames). Like a hardware interface
it stamps each frame: a frame sent without a time stamp gets the channel's clock (the simulated clock when one
is given, else `time.monotonic`; python-can's default stamp 0.0 counts as none); a frame sent with one (an emulated controller back-dating a frame to the
instant it fell due) keeps it. Tests may use python-can's `virtual` interface instead; this one exists because
the simulated bench must run hundreds of times faster than real time.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

import can

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
        self._queue: deque[can.Message] = deque()
        self._peers = _channels.setdefault(channel, [])
        self._peers.append(self)
        if clock is not None:
            _clocks[channel] = clock
        self._channel = channel

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not msg.timestamp:
            msg.timestamp = _clocks.get(self._channel, time.monotonic)()
        for bus in self._peers:
            if bus is not self or self.receive_own_messages:
                bus._queue.append(msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """Next frame; with a timeout, wait for one in wall-clock time (filters honoured via python-can)."""
        if self._filters:
            return super().recv(timeout)
        if self._queue:
            return self._queue.popleft()
        deadline = None if timeout is None else time.monotonic() + timeout
        while deadline is None or time.monotonic() < deadline:
            if self._queue:
                return self._queue.popleft()
            if timeout == 0:
                break
            time.sleep(_WAIT_S)
        return None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return (self._queue.popleft() if self._queue else None), False

    def shutdown(self) -> None:
        if self in self._peers:
            self._peers.remove(self)
        if not self._peers:
            _channels.pop(self._channel, None)
            _clocks.pop(self._channel, None)
        super().shutdown()
