"""`benchlab probe pt1000|node|can --url URL [--json] [--count N] [--bitrate BIT/S]`: read a few values from one
bench device.

Exit 0 with data, 1 when nothing arrived in time, 2 for a URL that does not open. Read-only: the PT1000
scanner is reset and configured (that is how it measures), the node and the CAN bus are only listened to. `sim://NAME` URLs reach the in-process emulators (sim_bench.emulators).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from typing import Any

from benchlab import cliargs
from benchlab.bounds import MAX_CAN_BITRATE, MAX_PROBE_READINGS, MAX_TIMEOUT_S, MIN_CAN_BITRATE
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held
from drivers.errors import ConnectionLost

NAME = "probe"
HELP = "read a few values from one bench device (pt1000 scanner, clutch node gateway, CAN controllers)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("device", choices=("pt1000", "node", "can"), help="which device to probe")
    parser.add_argument("--url", required=True,
                        help="pyserial URL (/dev/ttyUSB0, socket://host:5025, sim://instrument) or, for can, "
                             "INTERFACE:CHANNEL (socketcan:can0, virtual:bench)")
    parser.add_argument("--count", type=cliargs.count("a number of readings", MAX_PROBE_READINGS), default=None,
                        help="scans (pt1000, default 1) or frames (node/can, default 10) to read")
    parser.add_argument("--timeout", type=cliargs.positive_float("a time-out in s", MAX_TIMEOUT_S), default=2.0,
                        help="seconds to wait for data (default 2)")
    parser.add_argument("--channels", type=cliargs.channel_list, default="(@101:104)",
                        help="pt1000 channel list (default (@101:104))")
    parser.add_argument("--mode", choices=("fres", "frtd"), default="fres",
                        help="pt1000: 4-wire resistance + CVD in software, or the instrument's RTD conversion")
    parser.add_argument("--bitrate", type=cliargs.count("a CAN bit rate in bit/s", MAX_CAN_BITRATE, MIN_CAN_BITRATE),
                        help="can: the bus's bit rate in bit/s (e.g. 500000), for interfaces that set it "
                             "(socketcan takes the rate set with `ip link`)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of text lines")


def run(args: argparse.Namespace) -> int:
    if args.bitrate is not None and args.device != "can":
        raise InputError("command line", "--bitrate", f"only with `probe can` (a CAN bus), not {args.device}")
    if args.url.startswith("sim://"):
        with interrupts_held():  # each import of a driver or emulator is held: see benchlab.cli
            import sim_bench.emulators  # noqa: F401 - registers the sim:// pyserial handler
    report = {"pt1000": _probe_pt1000, "node": _probe_node, "can": _probe_can}[args.device](args)
    lines = report.pop("lines")
    print(json.dumps(report, default=str) if args.json else "\n".join(lines))
    return 0 if report.get("readings") or report.get("samples") else 1


def _probe_pt1000(args: argparse.Namespace) -> dict[str, Any]:
    with interrupts_held():
        from drivers.pt1000 import Pt1000Scanner

    scanner = _open(lambda: Pt1000Scanner.open(args.url, args.channels, mode=args.mode, timeout=args.timeout), args.url)
    try:
        idn = scanner.identify()
        scanner.reset()
        scans = [scanner.read() for _ in range(args.count or 1)]
    finally:
        scanner.close()
    lines = [f"{args.url}: {idn}"] + [
        f"  {r.channel}: {_num(r.resistance_ohm, 'Ω')}  {_num(r.temperature_c, '°C')}  {r.status}"
        for scan in scans for r in scan]
    lines += [f"  error queue: {e.code},{e.text}" for e in scanner.error_log]
    return {"device": "pt1000", "url": args.url, "idn": idn, "readings": [_row(r) for s in scans for r in s],
            "errors": [_row(e) for e in scanner.error_log], "lines": lines}


def _probe_node(args: argparse.Namespace) -> dict[str, Any]:
    with interrupts_held():
        from drivers.clutch_node import ClutchNodeGateway

    gateway = _open(lambda: ClutchNodeGateway.open(args.url), args.url)
    try:
        samples = gateway.read(args.count or 10, args.timeout)
    finally:
        gateway.close()
    lines = [f"{args.url}: {len(samples)} frames, {gateway.stats}"] + [
        f"  seq {s.seq:5d} t_node {s.node_time_ms:9d} ms  R {_num(s.resistance_ohm[0], 'Ω')} "
        f"{_num(s.resistance_ohm[1], 'Ω')}  T {_num(s.temperature_c[0], '°C')} {_num(s.temperature_c[1], '°C')}  "
        f"{'/'.join(s.sensor_status)}  {s.supply_mv} mV  {s.rssi_dbm} dBm  LQI {s.lqi}  flags 0x{s.flags:02x}"
        for s in samples]
    events = gateway.pop_events()
    lines += [f"  event: {e}" for e in events]
    return {"device": "node", "url": args.url, "samples": [_row(s) for s in samples],
            "stats": _row(gateway.stats), "events": [_row(e) for e in events], "lines": lines}


def _probe_can(args: argparse.Namespace) -> dict[str, Any]:
    with interrupts_held():
        import can

        from drivers.can_bench import CanBench

    interface, sep, channel = args.url.partition(":")
    if not sep or not interface or not channel:
        raise InputError("--url", args.url, "INTERFACE:CHANNEL for can, e.g. socketcan:can0 or virtual:bench")
    if interface not in can.interfaces.VALID_INTERFACES or interface == "udp_multicast":
        raise InputError("--url", args.url, f"a python-can interface other than udp_multicast, not {interface!r}")
    config = {"interface": interface, "channel": channel}
    if args.bitrate is not None:
        config["bitrate"] = args.bitrate
    bench = _open(lambda: CanBench.from_config(config, listen_only=True), args.url, can.CanError)
    samples = []
    try:
        deadline = time.monotonic() + args.timeout
        while True:  # the last poll starts after the deadline, so the watchdog has seen the whole time-out
            past = time.monotonic() >= deadline
            new = bench.poll()
            samples += new
            if past or len(samples) >= (args.count or 10):
                break
            if not new:
                time.sleep(0.002)
    finally:
        bench.close()
    events = bench.pop_events()
    lines = [f"{args.url}: {len(samples)} frames, {bench.stats}"] + [
        f"  {s.message:26s} " + " ".join(f"{k.split('.', 1)[1]}={v:g}" for k, v in s.values.items())
        for s in samples] + [f"  event: {e}" for e in events]
    return {"device": "can", "url": args.url, "samples": [_row(s) for s in samples], "stats": _row(bench.stats),
            "events": [_row(e) for e in events], "lines": lines}


def _open(opener: Any, url: str, *errors: type[Exception]) -> Any:
    """Run a driver's opener; a URL that does not open (an OSError, ..., or one of the driver's `errors`) is bad
    input (exit 2)."""
    try:
        return opener()
    except (ConnectionLost, OSError, ValueError, ImportError, *errors) as exc:
        raise InputError("--url", url, f"a device that opens ({exc})") from None


def _row(obj: Any) -> dict[str, Any]:
    return dataclasses.asdict(obj)


def _num(value: float | None, unit: str) -> str:
    return "—" if value is None else f"{value:.3f} {unit}"
