"""`benchlab probe pt1000|node|can --url URL [--json] [--count N] [--bitrate BIT/S]`, or `benchlab probe --bench
BENCH.toml`: read a few values from one bench device, or from every device of a bench.

Exit 0 with data from every device, 1 when one sent nothing in time, 2 for a device that does not open (one line
naming the setting: `--url`, or BENCH.toml's `[instrument] url`, `[node] url`, `[can]`; see
benchlab.runner.opening). With `--bench` every device is tried and reported, whichever fails, one verdict line
each (OK, WARN with what was counted, NO DATA, FAILED with why) and the bench's line; `-v` adds every reading
and frame, as a single device's probe prints them. Read-only: the
PT1000 scanner is reset and configured (that is how it measures), the node and the CAN bus are only listened to.
`sim://NAME` URLs reach the in-process emulators (sim_bench.emulators); for `can`, `sim://NAME` starts the
emulated bench controllers on an in-process bus of that name.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from benchlab import cliargs
from benchlab.bounds import MAX_CAN_BITRATE, MAX_PROBE_READINGS, MAX_TIMEOUT_S, MIN_CAN_BITRATE
from benchlab.errors import InputError
from benchlab.interrupts import interrupts_held

NAME = "probe"
HELP = "read a few values from one bench device (pt1000 scanner, clutch node gateway, CAN controllers) or every " \
       "device of a BENCH.toml"
DEVICES = ("pt1000", "node", "can")
_SOURCE = "command line"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("device", nargs="?", choices=DEVICES, help="which device to probe (all of them with --bench)")
    parser.add_argument("--url",
                        help="pyserial URL (/dev/ttyUSB0, socket://host:5025, sim://instrument), for pt1000 also a "
                             "VISA resource (TCPIP0::10.0.0.5::inst0::INSTR, GPIB0::9::INSTR), for can "
                             "INTERFACE:CHANNEL (socketcan:can0, virtual:bench) or sim://NAME (emulated controllers)")
    parser.add_argument("--bench", metavar="BENCH.toml", help="probe every device of this bench file and report each")
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
    if args.bench is not None:
        if args.device is not None or args.url is not None:
            raise InputError(_SOURCE, "--bench", "alone: the bench file names every device (no DEVICE, no --url)")
        reports = _probe_bench(args)
    else:
        if args.device is None or args.url is None:
            raise InputError(_SOURCE, "DEVICE --url", "a device and its URL (probe pt1000 --url URL), or --bench "
                                                      "BENCH.toml")
        if args.bitrate is not None and args.device != "can":
            raise InputError(_SOURCE, "--bitrate", f"only with `probe can` (a CAN bus), not {args.device}")
        reports = [_probe_one(args)]
    detail = args.bench is None or getattr(args, "verbose", 0) > 0
    lines = [line for r in reports for line in (r.pop("lines") if detail else [_verdict_line(r)])]
    if args.bench is not None:
        for r in reports:
            r.pop("lines", None)
        ok = sum(_verdict(r)[0] == "OK" for r in reports)
        lines += [f"{args.bench}: {ok} of {len(reports)} devices OK" + ("" if detail else
                                                                         " (-v: every reading and frame)")]
    document: Any = reports[0] if args.bench is None else {"bench": args.bench, "devices": reports}
    print(json.dumps(document, default=str) if args.json else "\n".join(lines))
    if any("error" in r for r in reports):  # --bench: a device that did not open (one alone raises: exit 2)
        return 2
    return 0 if all(r.get("readings") or r.get("samples") for r in reports) else 1


def _probe_one(args: argparse.Namespace) -> dict[str, Any]:
    """One device by --url: its report; a device that does not open raises (exit 2, naming --url)."""
    from benchlab.runner.opening import is_simulated

    if is_simulated(args.url) and args.device != "can":
        with interrupts_held():  # each import of a driver or emulator is held: see benchlab.cli
            import sim_bench.emulators  # noqa: F401 - registers the sim:// pyserial handler
    if args.device == "pt1000":
        return _probe_pt1000(args.url, args.channels, args.mode, args.timeout, args.count, _SOURCE, "--url")
    if args.device == "node":
        return _probe_node(args.url, {}, args.timeout, args.count, _SOURCE, "--url")
    return _probe_can(_can_config(args.url, args.bitrate), args.url, args.timeout, args.count, _SOURCE, "--url")


def _can_config(url: str, bitrate: int | None) -> dict[str, Any]:
    """python-can's config of INTERFACE:CHANNEL (or {"url": "sim://NAME"}), with the bit rate if given."""
    if url.startswith("sim://"):
        return {"url": url}
    interface, sep, channel = url.partition(":")
    if not sep or not interface or not channel:
        raise InputError("--url", url, "INTERFACE:CHANNEL for can, e.g. socketcan:can0 or virtual:bench, or "
                                       "sim://NAME")
    config: dict[str, Any] = {"interface": interface, "channel": channel}
    if bitrate is not None:
        config["bitrate"] = bitrate
    return config


def _probe_bench(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every device of BENCH.toml, each reported whether or not another failed; the simulated ones on one plant."""
    with interrupts_held():
        from benchlab.runner.clock import RealClock
        from benchlab.runner.config import load_bench_config
        from benchlab.runner.opening import DeviceOpenError, has_simulated_devices

    config = load_bench_config(args.bench)
    src = config.source
    devices = service = None
    if has_simulated_devices(config):
        with interrupts_held():
            from sim_bench.mixed import SimulatedDevices

        devices = SimulatedDevices(config, RealClock(), seed=1)
        config, service = devices.config, devices.service
    can_config = dict(config.can)
    probes: list[tuple[str, Callable[[], dict[str, Any]]]] = [
        ("pt1000", lambda: _probe_pt1000(config.instrument_url, sorted(config.instrument_channels),
                                         config.instrument_mode, config.instrument_timeout_s, args.count, src,
                                         "[instrument] url", baudrate=config.instrument_baudrate)),
        ("node", lambda: _probe_node(config.node_url, {"baudrate": config.node_baudrate}, args.timeout, args.count,
                                     src, "[node] url")),
        ("can", lambda: _probe_can(can_config, config.can.get("url") or _describe(can_config), args.timeout,
                                   args.count, src, "[can]", bus=devices.bus if devices is not None else None,
                                   service=service)),
    ]
    reports = []
    try:
        for device, probe in probes:
            try:
                reports.append(probe())
            except DeviceOpenError as exc:
                reports.append({"device": device, "error": str(exc), "lines": [f"{device}: {exc}"]})
    finally:
        if devices is not None:
            devices.close()
    return reports


def _describe(config: dict[str, Any]) -> str:
    return " ".join(f"{k}={v}" for k, v in config.items())


def _probe_pt1000(url: str, channels: Any, mode: str, timeout: float, count: int | None, source: str, key: str,
                  **kwargs: Any) -> dict[str, Any]:
    with interrupts_held():
        from benchlab.runner.opening import open_scanner

    scanner, idn = open_scanner(url, channels, source=source, key=key, mode=mode, timeout=timeout, **kwargs)
    try:
        scans = [scanner.read() for _ in range(count or 1)]
    finally:
        scanner.close()
    lines = [f"{url}: {idn}"] + [
        f"  {r.channel}: {_num(r.resistance_ohm, 'Ω')}  {_num(r.temperature_c, '°C')}  {r.status}"
        for scan in scans for r in scan]
    lines += [f"  error queue: {e.code},{e.text}" for e in scanner.error_log]
    return {"device": "pt1000", "url": url, "idn": idn, "readings": [_row(r) for s in scans for r in s],
            "errors": [_row(e) for e in scanner.error_log], "lines": lines}


def _probe_node(url: str, options: dict[str, Any], timeout: float, count: int | None, source: str,
                key: str) -> dict[str, Any]:
    with interrupts_held():
        from benchlab.runner.opening import open_gateway

    gateway = open_gateway(url, source=source, key=key, **options)
    try:
        samples = gateway.read(count or 10, timeout)
    finally:
        gateway.close()
    lines = [f"{url}: {len(samples)} frames, {gateway.stats}"] + [
        f"  seq {s.seq:5d} t_node {s.node_time_ms:9d} ms  R {_num(s.resistance_ohm[0], 'Ω')} "
        f"{_num(s.resistance_ohm[1], 'Ω')}  T {_num(s.temperature_c[0], '°C')} {_num(s.temperature_c[1], '°C')}  "
        f"{'/'.join(s.sensor_status)}  {s.supply_mv} mV  {s.rssi_dbm} dBm  LQI {s.lqi}  flags 0x{s.flags:02x}"
        for s in samples]
    events = gateway.pop_events()
    lines += [f"  event: {e}" for e in events]
    return {"device": "node", "url": url, "samples": [_row(s) for s in samples],
            "stats": _row(gateway.stats), "events": [_row(e) for e in events], "lines": lines}


def _probe_can(config: dict[str, Any], url: str, timeout: float, count: int | None, source: str, key: str, *,
               bus: Any = None, service: Callable[[], None] | None = None) -> dict[str, Any]:
    """Listen to the bus of `config` (python-can's keys; {"url": "sim://NAME"}: emulated controllers started here
    on an in-process bus NAME); `bus`/`service`: a bus already open and the emulators to run before each poll."""
    with interrupts_held():
        from benchlab.runner.opening import open_can_bus
        from drivers.can_bench import CanBench

    emulated = None
    if bus is None and "url" in config:
        emulated = _EmulatedControllers(config["url"][len("sim://"):].rstrip("/"))
        bus, service = emulated.driver_bus, emulated.poll
    elif bus is None:
        bus = open_can_bus(config, source=source, key=key)
    bench = CanBench(bus, listen_only=True)
    samples = []
    try:
        deadline = time.monotonic() + timeout
        while True:  # the last poll starts after the deadline, so the watchdog has seen the whole time-out
            past = time.monotonic() >= deadline
            if service is not None:
                service()
            new = bench.poll()
            samples += new
            if past or len(samples) >= (count or 10):
                break
            if not new:
                time.sleep(0.002)
    finally:
        bench.close()
        if emulated is not None:
            emulated.close()
    events = bench.pop_events()
    lines = [f"{url}: {len(samples)} frames, {bench.stats}"] + [
        f"  {s.message:26s} " + " ".join(f"{k.split('.', 1)[1]}={v:g}" for k, v in s.values.items())
        for s in samples] + [f"  event: {e}" for e in events]
    return {"device": "can", "url": url, "samples": [_row(s) for s in samples], "stats": _row(bench.stats),
            "events": [_row(e) for e in events], "lines": lines}


class _EmulatedControllers:
    """The bench controllers (sim_bench's emulator, its stand-alone drivetrain) on an in-process bus `name`."""

    def __init__(self, name: str) -> None:
        with interrupts_held():
            from sim_bench.emulators import CanBenchEmulator, SimCanBus

        self.emulator_bus, self.driver_bus = SimCanBus(name), SimCanBus(name)
        self.emulator = CanBenchEmulator(self.emulator_bus)

    def poll(self) -> None:
        self.emulator.poll()

    def close(self) -> None:
        self.emulator_bus.shutdown()


def _verdict(report: dict[str, Any]) -> tuple[str, str]:
    """A device's verdict (OK, WARN, NO DATA, FAILED) and in a few words what it answered or why not."""
    if "error" in report:
        return "FAILED", report["error"]
    if report["device"] == "pt1000":
        readings = report["readings"]
        odd = [f"{r['channel']} {r['status']}" for r in readings if r["status"] != "ok"]
        temps = ", ".join(f"{r['channel']} {_num(r['temperature_c'], '°C')}" for r in readings[:8])
        errors = [f"error {e['code']}" for e in report["errors"]]
        said = f"{report['url']}: {report['idn']}; {temps}" + "".join(f"; {w}" for w in odd + errors)
        return ("WARN" if odd or errors else "OK") if readings else "NO DATA", said
    samples, stats, events = report["samples"], report["stats"], report["events"]
    counted = [f"{n} {name.replace('_', ' ')}" for name, n in stats.items()
               if n and name not in ("frames_ok", "sent")]
    kinds = [" ".join(filter(None, (e.get("controller"), e["kind"].replace("_", " ")))) for e in events]
    counted += [f"{n} × {kind}" for kind, n in Counter(kinds).items()]
    if report["device"] == "node":
        last = samples[-1] if samples else None
        got = (f"{len(samples)} frames, T {_num(last['temperature_c'][0], '°C')} / "
               f"{_num(last['temperature_c'][1], '°C')}" if last else "no frames")
    else:
        controllers = sorted({s["controller"] for s in samples})
        got = f"{len(samples)} frames from {', '.join(controllers) or 'no controller'}"
    said = f"{report['url']}: {got}" + "".join(f"; {c}" for c in counted)
    return ("WARN" if counted else "OK") if samples else "NO DATA", said


def _verdict_line(report: dict[str, Any]) -> str:
    """One line per device for `probe --bench`."""
    verdict, said = _verdict(report)
    return f"{report['device']:7s} {verdict:8s} {said}"


def _row(obj: Any) -> dict[str, Any]:
    return dataclasses.asdict(obj)


def _num(value: float | None, unit: str) -> str:
    return "—" if value is None else f"{value:.3f} {unit}"
