"""Every exception a driver raises on purpose, as one tree under `DriverError` (python-can's `CanError` tree is the model).

    DriverError
    ├── DriverConfigError (also ValueError)   arguments a driver cannot work with
    ├── DeviceTimeout (also TimeoutError)      the device did not answer in time
    ├── ConnectionLost                         the transport failed; call `reconnect()`
    ├── InstrumentError                        the instrument reported errors or an unparsable reply
    ├── FrameError                             bytes that are not a valid frame
    │   ├── CobsError                          not a valid COBS encoding
    │   ├── MalformedFrame                     bad COBS, wrong length or unknown version
    │   └── CrcMismatch                        well-formed, CRC does not match
    └── CanDriverError                         raised by the CAN bench driver
        ├── CanConfigError (also DriverConfigError)   DBC or signal mapping unusable
        ├── CanBusError                        the bus failed to start, send or receive
        ├── CanTimeout (also DeviceTimeout)    the bus did not take a frame in time
        └── CanLogError                        the raw CAN log cannot be written

`except DriverError` catches everything a driver raises on purpose; `except TimeoutError` catches every time-out.
"""

from __future__ import annotations


class DriverError(Exception):
    """Base class of every error a driver raises on purpose."""


class DriverConfigError(DriverError, ValueError):
    """A driver was built or called with arguments it cannot work with (a mode, a channel list, a missing port)."""


class DeviceTimeout(DriverError, TimeoutError):
    """The device did not answer within the transport's timeout."""


class ConnectionLost(DriverError):
    """The transport failed (port closed, cable pulled, socket reset); call `reconnect()`."""


class InstrumentError(DriverError):
    """The instrument reported errors (its SCPI error queue) or sent a reply that cannot be parsed."""

    def __init__(self, message: str, entries: tuple[tuple[int, str], ...] = ()) -> None:
        self.entries = entries
        detail = "; ".join(f"{code},{text}" for code, text in entries)
        super().__init__(f"{message}: {detail}" if detail else message)


class FrameError(DriverError):
    """A delimited chunk that is not a valid frame; never becomes a reading."""


class CobsError(FrameError):
    """The bytes are not a valid COBS encoding."""


class MalformedFrame(FrameError):
    """Bad COBS, wrong length or unknown version."""


class CrcMismatch(FrameError):
    """Well-formed but the CRC does not match: corrupted on the way."""


class CanDriverError(DriverError):
    """Base class of the errors the CAN bench driver raises."""


class CanConfigError(CanDriverError, DriverConfigError):
    """The DBC cannot be read or lacks a message or signal the mapping names."""


class CanBusError(CanDriverError):
    """The CAN bus failed to start, send or receive (python-can's CanInitializationError/CanOperationError)."""


class CanTimeout(CanDriverError, DeviceTimeout):
    """The CAN bus did not take or deliver a frame within its time-out (python-can's CanTimeoutError)."""


class CanLogError(CanDriverError):
    """The raw CAN log (BLF/ASC) cannot be opened or written (disk full, no permission): the run must stop."""
