"""Opening the bench's devices, and the one line that says why one did not open.

A device that does not open is bad input (exit 2) naming the setting to fix (`[instrument] url` of BENCH.toml,
`--url` of probe), what was tried, why it failed in words, and what the machine has instead: the serial ports
(pyserial's `list_ports`), the CAN channels python-can finds on its cheap interfaces (socketcan, virtual), the
VISA resources a vendor VISA knows. python-can backends whose vendor library is missing fail in odd ways (kvaser:
NameError, pcan: OSError): they are caught and said as such.
"""

from __future__ import annotations

import errno
import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from benchlab.errors import InputError
from drivers.errors import DeviceTimeout, DriverError, InstrumentError

if TYPE_CHECKING:
    from benchlab.runner.devices import BenchConfig

log = logging.getLogger(__name__)

#: python-can interfaces whose search for channels is cheap and local (no vendor library, no network).
CHEAP_CAN_INTERFACES = ("socketcan",)  # python-can's `virtual` would only invent a channel name
_ERRNO_WORDS = {
    errno.ENOENT: "no such device or file",
    errno.EACCES: "permission denied (on Linux, is the user in the dialout group?)",
    errno.EPERM: "permission denied",
    errno.EBUSY: "busy: another program has it open",
    errno.ECONNREFUSED: "connection refused: nothing listens there",
    errno.EHOSTUNREACH: "host unreachable",
    errno.ENETUNREACH: "network unreachable",
    errno.ETIMEDOUT: "no answer (timed out)",
    errno.ENODEV: "no such device",
    errno.ENXIO: "no such device (unplugged?)",
    errno.EAFNOSUPPORT: "this system has no support for it (no CAN in the kernel?)",
}


class DeviceOpenError(InputError):
    """A bench device did not open: `source` (BENCH.toml or "command line"), the `key` naming the setting, what
    was `tried`, `why` in words and what `exists` instead, on one line; exit 2."""

    def __init__(self, source: str, key: str, tried: str, why: str, exists: str) -> None:
        self.key, self.tried, self.why, self.exists = key, tried, why, exists
        super().__init__(source, key, f"{tried} did not open: {why}" + (f"; {exists}" if exists else ""))


def reason(exc: BaseException) -> str:
    """Why an open failed, in words: the errno's meaning, a VISA status's description, a time-out, the first line
    of a library's message (the innermost cause's; repeated paths and class names left out)."""
    root = exc
    while root.__cause__ is not None and root.__cause__ is not root:
        root = root.__cause__
    code = getattr(root, "errno", None)
    if isinstance(code, int) and code in _ERRNO_WORDS:
        return _ERRNO_WORDS[code]
    if isinstance(root, NameError):  # python-can's kvaser (and others) when the vendor library is missing
        return f"its vendor library is not installed (python-can failed on {root.name or 'a missing name'!r})"
    if isinstance(exc, DeviceTimeout):
        return f"no answer ({_first_line(exc)})"
    if isinstance(exc, InstrumentError):
        return f"the instrument answered with errors ({_first_line(exc)})"
    description = getattr(root, "description", None)  # pyvisa's VisaIOError
    if description:
        return _first_line(description)
    strerror = getattr(root, "strerror", None)
    if isinstance(strerror, str) and strerror:
        return strerror
    return _first_line(root) or type(root).__name__


def _first_line(text: object) -> str:
    """A library's message as one sentence: its first line, up to its first full stop, without the stop."""
    line = " ".join((str(text).strip().splitlines() or [""])[0].split())
    sentence = line.split(". ", 1)[0]
    return sentence[:-1] if sentence.endswith(".") else sentence


def serial_ports() -> str:
    """The serial ports of this machine, as probe and open failures list them."""
    try:
        from serial.tools import list_ports

        ports = sorted(list_ports.comports(), key=lambda p: p.device)
    except Exception as exc:  # noqa: BLE001 - a listing that fails is said, never raised
        return f"serial ports cannot be listed ({reason(exc)})"
    if not ports:
        return "no serial ports here"
    return "serial ports here: " + ", ".join(
        p.device + (f" ({p.description})" if p.description and p.description != "n/a" else "") for p in ports)


def visa_resources(backend: str) -> str:
    """The VISA resources a vendor VISA knows; pyvisa-py is not asked (its search broadcasts on the LAN)."""
    from drivers.visa_port import DEFAULT_BACKEND, resource_manager

    if backend == DEFAULT_BACKEND:
        return "VISA resources not searched (pyvisa-py would broadcast on the LAN); " + serial_ports()
    try:
        found = resource_manager(backend).list_resources()
    except Exception as exc:  # noqa: BLE001 - a listing that fails is said, never raised
        return f"VISA resources cannot be listed ({reason(exc)})"
    return "VISA resources here: " + (", ".join(found) if found else "none")


def can_channels() -> str:
    """The CAN channels python-can finds on its cheap interfaces, and the interfaces it has."""
    import can

    try:
        found = can.detect_available_configs(interfaces=list(CHEAP_CAN_INTERFACES))
    except Exception as exc:  # noqa: BLE001 - a listing that fails is said, never raised
        return f"CAN channels cannot be listed ({reason(exc)})"
    channels = ", ".join(f"{c['interface']}:{c['channel']}" for c in found) or "none"
    return f"CAN channels here ({'/'.join(CHEAP_CAN_INTERFACES)}): {channels}"


def can_interfaces() -> str:
    """python-can's interfaces by name (udp_multicast left out: it leaves the machine)."""
    import can

    return "python-can's interfaces: " + ", ".join(sorted(i for i in can.interfaces.VALID_INTERFACES
                                                          if i != "udp_multicast"))


def _opened(opener: Callable[[], Any], source: str, key: str, tried: str, exists: Callable[[], str]) -> Any:
    try:
        return opener()
    except (DriverError, OSError, ValueError, ImportError, NameError, AttributeError, TypeError) as exc:
        log.debug("%s %s: %r", key, tried, exc, exc_info=True)
        raise DeviceOpenError(source, key, tried, reason(exc), exists()) from None
    except Exception as exc:  # noqa: BLE001 - a backend's own error class (python-can's CanError, pyvisa's)
        if type(exc).__module__.split(".")[0] not in ("can", "pyvisa", "pyvisa_py", "serial", "usb", "gpib"):
            raise
        log.debug("%s %s: %r", key, tried, exc, exc_info=True)
        raise DeviceOpenError(source, key, tried, reason(exc), exists()) from None


def open_scanner(url: str, channels: Any, *, source: str, key: str = "[instrument] url", **kwargs: Any) -> Any:
    """The PT1000 scanner at `url`, identified (`*IDN?`) and reset: (scanner, idn); DeviceOpenError naming `key`."""
    from drivers.pt1000 import Pt1000Scanner
    from drivers.visa_port import DEFAULT_BACKEND, is_visa_resource

    exists = (lambda: visa_resources(DEFAULT_BACKEND)) if is_visa_resource(url) else serial_ports
    scanner = _opened(lambda: Pt1000Scanner.open(url, channels, **kwargs), source, key, repr(url), exists)
    try:
        idn = _opened(scanner.identify, source, key, f"{url!r} (*IDN?)", exists)
        _opened(scanner.reset, source, key, f"{url!r} (*RST, configure)", lambda: "")
    except DeviceOpenError:
        _close_quietly(scanner.close)
        raise
    log.info("scanner %s: %s", url, idn)
    return scanner, idn


def open_gateway(url: str, *, source: str, key: str = "[node] url", **kwargs: Any) -> Any:
    """The clutch node's PC gateway at `url`; DeviceOpenError naming `key`."""
    from drivers.clutch_node import ClutchNodeGateway

    gateway = _opened(lambda: ClutchNodeGateway.open(url, **kwargs), source, key, repr(url), serial_ports)
    log.info("node gateway %s open", url)
    return gateway


def open_can_bus(config: Mapping[str, Any], *, source: str, key: str = "[can]") -> Any:
    """python-can's bus for `config` (can.Bus(**config)); DeviceOpenError naming `key` and listing what exists."""
    import can

    interface = config.get("interface")
    tried = " ".join(f"{k}={v!r}" for k, v in config.items())

    def exists() -> str:
        if interface not in can.interfaces.VALID_INTERFACES:
            return can_interfaces()
        return can_channels()

    if interface not in can.interfaces.VALID_INTERFACES or interface == "udp_multicast":
        raise DeviceOpenError(source, f"{key} interface" if key.startswith("[") else key, repr(interface),
                              "not a python-can interface" if interface != "udp_multicast" else
                              "udp_multicast leaves the machine, not allowed", exists())
    bus = _opened(lambda: can.Bus(**dict(config)), source, key, tried, exists)
    log.info("CAN bus %s open: %s", tried, getattr(bus, "channel_info", ""))
    return bus


def _close_quietly(closer: Callable[[], None]) -> None:
    try:
        closer()
    except Exception:  # noqa: BLE001 - closing a device that half opened is best effort
        pass


def is_simulated(url: object) -> bool:
    """Whether a device address names an emulated device of the simulated plant (`sim://NAME`)."""
    return isinstance(url, str) and url.startswith("sim://")


def has_simulated_devices(config: "BenchConfig") -> bool:
    """Whether any device of a BENCH.toml is `sim://NAME` (then sim_bench.mixed serves them, on one plant)."""
    return any(is_simulated(u) for u in (config.instrument_url, config.node_url, config.can.get("url")))
