"""pyserial URL handler `sim://NAME`: a serial port whose far end is an in-process emulator.

Registered by importing sim_bench.emulators. Reads pull what the endpoint produced up to its clock; with a
timeout and nothing available they wait in wall-clock time like a real port (use timeout=0 in simulated time).
A disconnected endpoint makes open/read/write raise SerialException, as a pulled USB adapter does.
"""

from __future__ import annotations

import time
import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from sim_bench.emulators import registry

_WAIT_S = 0.001


class Serial(SerialBase):
    """pyserial Serial API over a registry endpoint."""

    def open(self) -> None:
        """Look the endpoint up and connect; SerialException if unknown or disconnected."""
        if self.is_open:
            raise SerialException("Port is already open.")
        name = self.from_url(self.portstr)
        try:
            self._endpoint = registry.lookup(name)
        except KeyError:
            raise SerialException(f"sim://{name}: no emulator registered under that name") from None
        self._check()
        self._rx = bytearray()
        self.is_open = True

    def from_url(self, url: str) -> str:
        """The endpoint name of `sim://NAME`."""
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "sim" or not parts.netloc:
            raise SerialException(f"expected sim://NAME, got {url!r}")
        return parts.netloc

    def _reconfigure_port(self) -> None:
        """Baud rate and framing mean nothing here."""

    def close(self) -> None:
        self.is_open = False

    @property
    def in_waiting(self) -> int:
        self._pull()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        self._pull()
        if len(self._rx) < size:  # wait in wall-clock time for the rest
            deadline = None if self.timeout is None else time.monotonic() + self.timeout
            while len(self._rx) < size and (deadline is None or time.monotonic() < deadline):
                time.sleep(_WAIT_S)
                self._pull()
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        """Up to and including `expected` (or `size` bytes); works with timeout=0 in simulated time."""
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        self._pull()
        while (expected not in self._rx and (size is None or len(self._rx) < size)
               and (deadline is None or time.monotonic() < deadline)):
            time.sleep(_WAIT_S)
            self._pull()
        end = self._rx.find(expected)
        n = len(self._rx) if end < 0 else end + len(expected)
        n = n if size is None else min(n, size)
        data = bytes(self._rx[:n])
        del self._rx[:n]
        return data

    def write(self, data: bytes) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        self._check()
        self._endpoint.write(bytes(data))
        return len(data)

    def reset_input_buffer(self) -> None:
        self._pull()
        self._rx.clear()

    def reset_output_buffer(self) -> None:
        """Writes are delivered at once; nothing to drop."""

    def _pull(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        self._check()
        self._rx += self._endpoint.read_available()

    def _check(self) -> None:
        if not self._endpoint.connected:
            raise SerialException(f"{self.portstr}: device disconnected")
