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
import re
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


#: pyserial's URL schemes (serial.urlhandler) a bench device may use, and which of them name a host and a port.
SERIAL_SCHEMES = ("socket", "rfc2217", "loop", "spy", "hwgrep", "alt", "cp2110")
_NETWORK_SCHEMES = ("socket", "rfc2217")
_HOST = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252}[A-Za-z0-9])?|\[[0-9A-Fa-f:.]{2,45}\]")
_DEVICE_PATH = re.compile(r"/[^\s]{1,250}|COM[1-9]\d{0,2}")
_GPIB_ADDRESSES = range(31)
_PORTS = range(1, 65536)


def _host_port_problem(host: str | None, port: "int | str | None") -> str | None:
    """What is wrong with a network device's host and port (a name or address; a port 1-65535), None if nothing."""
    if not host or not _HOST.fullmatch(host):
        return f"a host name or address, got {host!r}"
    if port is not None and not (str(port).isdigit() and int(port) in _PORTS):
        return f"a port from 1 to 65535, got {port!r}"
    return None


def address_problem(url: str) -> str | None:
    """What makes `url` no device address at all, judged by its text alone (nothing is opened): a VISA resource
    string (parsed by pyvisa; its host and port, a GPIB address 0-30), a pyserial URL (a known scheme; a host and a
    port 1-65535 for socket:// and rfc2217://), a device path (/dev/..., COMn) or sim://NAME. None where it may be
    one; whether the device is there is for opening it to say."""
    from drivers.visa_port import is_visa_resource

    if not url.isprintable() or len(url) > 256:
        return "printable text of at most 256 characters"
    if is_simulated(url):
        return None if len(url) > len("sim://") else "sim://NAME"
    if is_visa_resource(url):
        from pyvisa import rname

        try:
            resource = rname.parse_resource_name(url)
        except (rname.InvalidResourceName, ValueError) as exc:
            return f"a VISA resource string ({_first_line(exc)})"
        if hasattr(resource, "host_address"):
            return _host_port_problem(resource.host_address, getattr(resource, "port", None))
        primary = getattr(resource, "primary_address", None)
        if primary is not None and not (str(primary).isdigit() and int(primary) in _GPIB_ADDRESSES):
            return f"a GPIB address from 0 to 30, got {primary!r}"
        return None
    scheme, sep, rest = url.partition("://")
    if not sep and not _DEVICE_PATH.fullmatch(url):
        return "a device path (/dev/ttyUSB0, COM3), a pyserial URL or a VISA resource"
    if not sep:
        return None
    if scheme not in SERIAL_SCHEMES:
        return f"a pyserial URL scheme ({', '.join(SERIAL_SCHEMES)}) or a VISA resource, got {scheme!r}"
    if scheme in _NETWORK_SCHEMES:
        host, colon, port = rest.split("/", 1)[0].split("?", 1)[0].rpartition(":")
        return _host_port_problem(host, port) if colon else f"{scheme}://HOST:PORT"
    return None


def check_address(url: str, *, source: str, key: str) -> str:
    """`url` if it may be a device address (address_problem); else InputError naming `key` of `source`."""
    problem = address_problem(url)
    if problem is not None:
        raise InputError(source, key, f"a device address: {problem}, got {url!r}")
    return url


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

    check_address(url, source=source, key=key)
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

    check_address(url, source=source, key=key)
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


def simulated_devices(config: "BenchConfig") -> str:
    """A BENCH.toml's `sim://` devices in words for the run's provenance, e.g. "node sim://rig, CAN sim://rig"
    ("" for none)."""
    named = (("instrument", config.instrument_url), ("node", config.node_url), ("CAN", config.can.get("url")))
    return ", ".join(f"{role} {url}" for role, url in named if is_simulated(url))


def has_simulated_devices(config: "BenchConfig") -> bool:
    """Whether any device of a BENCH.toml is `sim://NAME` (then sim_bench.mixed serves them, on one plant)."""
    return any(is_simulated(u) for u in (config.instrument_url, config.node_url, config.can.get("url")))
