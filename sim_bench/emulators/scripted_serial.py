"""A scripted fake serial port for byte-level driver tests (PyMeasure `expected_protocol` style).

The script is a list of (bytes the driver must send, bytes the device answers); pairs with empty "sent"
bytes are unsolicited data, delivered as soon as the script reaches them.
"""

from __future__ import annotations

from collections.abc import Sequence


class ScriptedSerial:
    """pyserial-like port: a write that deviates from the script raises AssertionError naming both."""

    def __init__(self, script: Sequence[tuple[bytes, bytes]], timeout: float | None = 0.0,
                 close_error: Exception | None = None) -> None:
        self.script = list(script)
        self.timeout = timeout
        self.close_error = close_error  # raised by close(), as by a port whose USB device vanished
        self.is_open = True
        self._pending = b""
        self._rx = bytearray()
        self._advance()

    @property
    def in_waiting(self) -> int:
        return len(self._rx)

    def write(self, data: bytes) -> int:
        self._pending += bytes(data)
        while self.script and self._pending:
            expected = self.script[0][0]
            if not (self._pending.startswith(expected) or expected.startswith(self._pending)):
                raise AssertionError(f"driver sent {self._pending!r}, script expected {expected!r}")
            if len(self._pending) < len(expected):
                break
            self._pending = self._pending[len(expected):]
            self._rx += self.script.pop(0)[1]
            self._advance()
        if self._pending and not self.script:
            raise AssertionError(f"driver sent {self._pending!r} after the script ended")
        return len(data)

    def deliver(self, data: bytes) -> None:
        """Unsolicited bytes from the device, arriving now."""
        self._rx += data

    def read(self, size: int = 1) -> bytes:
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        end = self._rx.find(expected)
        n = len(self._rx) if end < 0 else end + len(expected)
        return self.read(n if size is None else min(n, size))

    def reset_input_buffer(self) -> None:
        self._rx.clear()

    def open(self) -> None:
        self.is_open = True

    def close(self) -> None:
        if self.close_error is not None:
            raise self.close_error
        self.is_open = False

    @property
    def finished(self) -> bool:
        """True once every scripted exchange happened and every reply was read."""
        return not self.script and not self._pending and not self._rx

    def _advance(self) -> None:
        while self.script and not self.script[0][0]:
            self._rx += self.script.pop(0)[1]
