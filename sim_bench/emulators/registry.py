"""Named serial endpoints for the `sim://NAME` pyserial URL handler, with lazily created defaults."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol


class SerialEndpoint(Protocol):
    """A device behind a simulated serial port: bytes from the host in, bytes for the host out."""

    connected: bool

    def write(self, data: bytes) -> None: ...
    def read_available(self) -> bytes: ...


_endpoints: dict[str, SerialEndpoint] = {}
_defaults: dict[str, Callable[[], SerialEndpoint]] = {}


def register(name: str, endpoint: SerialEndpoint) -> None:
    """Make `endpoint` reachable as `sim://name` (replacing any previous one)."""
    _endpoints[name] = endpoint


def unregister(name: str) -> None:
    """Forget `sim://name`; a default is created again on the next open."""
    _endpoints.pop(name, None)


def set_default(name: str, factory: Callable[[], SerialEndpoint]) -> None:
    """Create `sim://name` with `factory` the first time it is opened without a registered endpoint."""
    _defaults[name] = factory


def lookup(name: str) -> SerialEndpoint:
    """The endpoint named `name`, creating its default if needed; KeyError if there is neither."""
    if name not in _endpoints:
        _endpoints[name] = _defaults[name]()
    return _endpoints[name]


@contextmanager
def unplugged(endpoint: SerialEndpoint) -> Iterator[None]:
    """The endpoint's cable is out for the duration of the block (its port's open/read/write raise)."""
    endpoint.connected = False
    try:
        yield
    finally:
        endpoint.connected = True
