"""A VISA message-based resource (`TCPIP0::10.0.0.5::inst0::INSTR`, `GPIB0::9::INSTR`, `USB0::…::INSTR`,
`TCPIP0::host::5025::SOCKET`) behind the part of pyserial's port API the SCPI driver uses (pt1000.SerialPort).

PyVISA with the pure-Python pyvisa-py backend (`@py`) by default; `backend` names another (a vendor VISA: "" or a
library path). VISA is message based: a reply is read as a whole after a query, and a read blocks. So that the
acquisition loop never waits, each query's reply is read by a worker thread and lands in a byte buffer the driver
takes from as from a serial port (`in_waiting`, `read`, `read_until`). Transport failures raise pyserial's
SerialException, which the driver turns into ConnectionLost as for any port.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from typing import Any

import serial

log = logging.getLogger(__name__)

DEFAULT_BACKEND = "@py"
#: A VISA resource string: interface type and board, then `::`-separated parts (VISA spec, resource names).
_RESOURCE = re.compile(r"(?:TCPIP|GPIB|USB|ASRL|VXI|GPIB-VXI|PXI|VICP)[\w/.-]*::.+", re.IGNORECASE)


def is_visa_resource(url: str) -> bool:
    """Whether `url` is a VISA resource string rather than a pyserial URL or device path."""
    return bool(_RESOURCE.fullmatch(url))


def resource_manager(backend: str = DEFAULT_BACKEND) -> Any:
    """PyVISA's resource manager of `backend`; ImportError/OSError/ValueError where it cannot be loaded."""
    import pyvisa

    return pyvisa.ResourceManager(backend)


class VisaPort:
    """pyserial-like port over a VISA resource; replies to queries (lines with `?`) are read in the background."""

    def __init__(self, resource_name: str, *, timeout: float = 2.0, backend: str = DEFAULT_BACKEND) -> None:
        self.resource_name, self.backend = resource_name, backend
        self._timeout = timeout
        self._rx = bytearray()
        self._lock = threading.Condition()
        self._queries = 0  # replies the worker is still to read
        self._failure: Exception | None = None  # a transport failure the worker met, raised on the next call
        self._resource: Any = None
        self._worker: threading.Thread | None = None
        self.open()

    @property
    def timeout(self) -> float:
        return self._timeout

    @timeout.setter
    def timeout(self, value: float) -> None:
        self._timeout = value
        if self._resource is not None:
            self._resource.timeout = value * 1000.0

    @property
    def is_open(self) -> bool:
        return self._resource is not None

    def open(self) -> None:
        """Open the resource (a SOCKET one with LF as its reply terminator) and start the reply reader."""
        import pyvisa

        try:
            resource = resource_manager(self.backend).open_resource(self.resource_name, read_termination="\n",
                                                                    write_termination="")
        except pyvisa.errors.VisaIOError as exc:
            raise serial.SerialException(exc.description) from exc
        resource.timeout = self._timeout * 1000.0
        with self._lock:
            self._resource, self._queries, self._failure = resource, 0, None
            self._rx.clear()
        self._worker = threading.Thread(target=self._read_replies, args=(resource,), name="visa-replies",
                                        daemon=True)
        self._worker.start()
        log.info("VISA %s open (backend %s)", self.resource_name, self.backend)

    def close(self) -> None:
        """Close the resource; the reply reader ends."""
        with self._lock:
            resource, self._resource = self._resource, None
            self._lock.notify_all()
        if resource is not None:
            try:
                resource.close()
            except Exception as exc:  # noqa: BLE001 - pyvisa's errors by backend: closing is best effort
                log.debug("VISA %s close: %s", self.resource_name, exc)
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout=self._timeout + 1.0)

    def write(self, data: bytes) -> int:
        """Send `data` (whole lines); each query in it has its reply read in the background."""
        resource = self._usable()
        try:
            resource.write_raw(bytes(data))
        except Exception as exc:  # noqa: BLE001 - pyvisa's errors by backend (VisaIOError, OSError)
            raise serial.SerialException(f"{self.resource_name}: {_reason(exc)}") from exc
        queries = sum(1 for line in bytes(data).split(b"\n") if b"?" in line)
        if queries:
            with self._lock:
                self._queries += queries
                self._lock.notify_all()
        return len(data)

    @property
    def in_waiting(self) -> int:
        self._usable()
        with self._lock:
            return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes, waiting at most the time-out for them."""
        return self._take(lambda rx: len(rx) >= size, lambda rx: size)

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        """Up to and including `expected` (or `size` bytes), waiting at most the time-out."""
        def count(rx: bytearray) -> int:
            end = rx.find(expected)
            n = len(rx) if end < 0 else end + len(expected)
            return n if size is None else min(n, size)
        return self._take(lambda rx: expected in rx or (size is not None and len(rx) >= size), count)

    def reset_input_buffer(self) -> None:
        """Drop the replies already received (a late one to a timed-out query is not the next query's)."""
        self._usable()
        with self._lock:
            self._rx.clear()

    def _take(self, ready: Any, count: Any) -> bytes:
        self._usable()
        deadline = time.monotonic() + self._timeout
        with self._lock:
            while not ready(self._rx) and self._failure is None and time.monotonic() < deadline:
                self._lock.wait(max(0.0, deadline - time.monotonic()))
            n = count(self._rx)
            data = bytes(self._rx[:n])
            del self._rx[:n]
        return data

    def _usable(self) -> Any:
        with self._lock:
            if self._failure is not None:
                failure, self._failure = self._failure, None
                raise serial.SerialException(f"{self.resource_name}: {_reason(failure)}") from failure
            if self._resource is None:
                raise serial.PortNotOpenError()
            return self._resource

    def _read_replies(self, resource: Any) -> None:
        """The worker: one whole reply per query sent; a time-out drops that query's reply (the driver times out
        on its own clock), any other failure is kept for the driver's next call and ends the worker."""
        import pyvisa

        while True:
            with self._lock:
                while self._queries == 0 and self._resource is resource:
                    self._lock.wait()
                if self._resource is not resource:
                    return
            try:
                reply = resource.read_raw()
            except pyvisa.errors.VisaIOError as exc:
                if exc.error_code == pyvisa.constants.StatusCode.error_timeout:
                    with self._lock:
                        self._queries = max(0, self._queries - 1)
                    continue
                self._fail(resource, exc)
                return
            except Exception as exc:  # noqa: BLE001 - a closed socket or session: reported to the driver
                self._fail(resource, exc)
                return
            with self._lock:
                self._queries = max(0, self._queries - 1)
                self._rx += reply if reply.endswith(b"\n") else reply + b"\n"
                self._lock.notify_all()

    def _fail(self, resource: Any, exc: Exception) -> None:
        with self._lock:
            if self._resource is resource:  # not a read ended by close()
                self._failure = exc
            self._lock.notify_all()


def _reason(exc: Exception) -> str:
    """A VISA or socket failure in words (VisaIOError's description, else the exception's text)."""
    return str(getattr(exc, "description", "") or exc or type(exc).__name__)
