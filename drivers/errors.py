"""Exceptions shared by the drivers: a transport that stopped answering or vanished, and instrument-side errors."""

from __future__ import annotations


class DriverError(Exception):
    """Base class of every error a driver raises on purpose."""


class DeviceTimeout(DriverError):
    """The device did not answer within the transport's timeout."""


class ConnectionLost(DriverError):
    """The transport failed (port closed, cable pulled, socket reset); call `reconnect()`."""


class InstrumentError(DriverError):
    """The instrument reported errors (its SCPI error queue) or sent a reply that cannot be parsed."""

    def __init__(self, message: str, entries: tuple[tuple[int, str], ...] = ()) -> None:
        self.entries = entries
        detail = "; ".join(f"{code},{text}" for code, text in entries)
        super().__init__(f"{message}: {detail}" if detail else message)


class CanLogError(DriverError):
    """The raw CAN log could not be written (disk full, no permission): the run must stop."""
