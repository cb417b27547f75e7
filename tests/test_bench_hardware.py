"""First contact with hardware (issue 34): a VISA scanner on loopback, device-open failures as one line naming the
BENCH.toml key, partly simulated benches, probe --bench, and the logs (-vv shows the SCPI dialogue, --log)."""

from __future__ import annotations

import functools
import subprocess
import sys
import time
from pathlib import Path

import can
import h5py
import numpy as np
import pytest

from benchlab.cli import main
from benchlab.runner import clock as runner_clock
from benchlab.runner import session
from drivers.errors import ConnectionLost, DriverError
from host_lag import HostLag
from drivers.pt1000 import Pt1000Scanner
from sim_bench.emulators import CanBenchEmulator, ConstantResistances, RealtimeLoop, ScpiInstrumentEmulator
from sim_bench.emulators.scpi_server import ScpiSocketServer

CHANNELS = """
[instrument.channels]
101 = "T_air"
102 = "T_housing"
103 = "T_ambient"
"""


def _bench(tmp_path: Path, instrument: str, node: str, can_table: str, name: str = "bench.toml") -> Path:
    path = tmp_path / name
    path.write_text(f'[instrument]\nurl = "{instrument}"\n{CHANNELS}\n[node]\nurl = "{node}"\n\n[can]\n{can_table}\n')
    return path


@pytest.fixture
def scpi_server():
    """The SCPI emulator (the serial emulator's dialogue) served on 127.0.0.1, three PT1000 at 40 °C."""
    provider = ConstantResistances({101: 1155.408, 102: 1155.408, 103: 1155.408})
    with ScpiSocketServer(ScpiInstrumentEmulator(provider)) as server:
        yield server


def test_scanner_through_visa_socket_speaks_the_serial_dialogue(scpi_server) -> None:
    scanner = Pt1000Scanner.open(scpi_server.resource, [101, 102, 103], timeout=2.0)
    try:
        assert "DAQ970A" in scanner.identify()
        scanner.reset()
        assert [round(r.temperature_c, 2) for r in scanner.read()] == [40.0, 40.0, 40.0]
        scanner.start_scan()  # the loop's way: never waits, the reply is collected when it is there
        deadline = time.monotonic() + 5.0
        while (readings := scanner.collect()) is None and time.monotonic() < deadline:
            time.sleep(0.001)
        assert readings is not None and [r.status for r in readings] == ["ok"] * 3
    finally:
        scanner.close()
    assert scpi_server.endpoint.commands[0] == "*IDN?" and "READ?" in scpi_server.endpoint.commands


@pytest.mark.parametrize("transport", ["visa", "socket"])
def test_a_reply_already_there_is_taken_in_one_collect(transport, scpi_server) -> None:
    """The loop collects once per tick: a reply waiting is taken whole (pyserial's socket:// says one byte is
    waiting whenever any is: the reply took a tick per byte, a scan seconds)."""
    url = scpi_server.resource if transport == "visa" else f"socket://127.0.0.1:{scpi_server.port}"
    scanner = Pt1000Scanner.open(url, [101, 102, 103], timeout=5.0)
    try:
        scanner.identify()
        scanner.reset()
        scanner.start_scan()
        collects, readings = 0, None
        while readings is None and collects < 10:
            time.sleep(0.1)  # a tick: READ?'s reply, then SYST:ERR?'s, is there by the next one (or the one after)
            readings = scanner.collect()
            collects += 1
        assert readings is not None and collects <= 4  # 2 where the machine keeps up; one byte a tick: 100
    finally:
        scanner.close()


def test_node_frames_through_socket_are_taken_whole_each_poll() -> None:
    """The node gateway behind a serial-to-LAN converter (socket://): a poll takes every frame already there."""
    from drivers import clutch_node as gateway_module
    from drivers.clutch_node import ClutchNodeGateway
    from sim_bench.emulators import ClutchNodeEmulator, clutch_node

    for module in (clutch_node, gateway_module):  # compiled before the clock matters (numba's cache)
        module.prime()
    with HostLag() as lag, ScpiSocketServer(ClutchNodeEmulator(period_s=0.05)) as server:  # node frames
        gateway = ClutchNodeGateway.open(f"socket://127.0.0.1:{server.port}", period_s=0.05)
        try:
            time.sleep(0.6)  # about 12 frames (300 bytes) waiting
            samples = gateway.poll()
        finally:
            gateway.close()
    with lag.judged(0.15):  # the emulator kept from its core 0.2 s sends 4 frames fewer (tests/host_lag.py)
        assert len(samples) >= 8  # one byte a poll: none


def test_a_lost_visa_instrument_is_connection_lost_then_reconnects() -> None:
    server = ScpiSocketServer(ScpiInstrumentEmulator())
    scanner = Pt1000Scanner.open(server.resource, [101], timeout=0.3)
    try:
        assert "DAQ970A" in scanner.identify()
        server.close()  # the instrument goes away: a time-out, then the transport's failure
        with pytest.raises(DriverError):
            scanner.identify()
        with pytest.raises(ConnectionLost):
            scanner.identify()
        with ScpiSocketServer(ScpiInstrumentEmulator(), port=server.port):  # back on its address
            scanner.reconnect()
            assert "DAQ970A" in scanner.identify()
    finally:
        scanner.close()


def test_vv_shows_the_scpi_dialogue(scpi_server, capsys) -> None:
    assert main(["-vv", "probe", "pt1000", "--url", scpi_server.resource, "--channels", "(@101:103)"]) == 0
    err = capsys.readouterr().err
    assert "DEBUG drivers.pt1000: SCPI > *IDN?" in err
    assert "DEBUG drivers.pt1000: SCPI < b'Keysight Technologies,DAQ970A" in err
    assert "SCPI > READ?" in err and "SCPI < b'+1.15540800E+03" in err


def test_table1_runs_with_a_visa_socket_scanner(scpi_server, tmp_path, monkeypatch, capsys) -> None:
    """A Table 1 run end to end: the scanner a VISA TCPIP SOCKET instrument on loopback, node and controllers
    simulated (one plant), on the real clock run twice as fast (every device answers on loopback or in process;
    at 4x a loaded machine's stalls outlast the controllers' command time-out and silence limits), its log kept
    beside the run file. Seed 17 draws a 40 s cycle that can synchronise (65 N·m × 15 > 100 N·m); an interlock
    aborts the run (a failure ends the test at once, not after the 1800 s a hold may last)."""
    bench = _bench(tmp_path, scpi_server.resource, "sim://visa-node", 'url = "sim://visa-can"')
    bench.write_text(bench.read_text() + '\n[limits]\non_interlock = "abort"\n')
    monkeypatch.setattr(session, "RealClock", functools.partial(runner_clock.RealClock, speed=2.0))
    out = tmp_path / "run.h5"
    with HostLag() as lag:
        code = main(["run", "table1", "--bench", str(bench), "--cycles", "1", "--seed", "17", "--out", str(out),
                     "-q", "--log"])
    # the emulated controllers answer on the wall clock: where the host kept a thread from its core longer than their
    # command time-out, an interlock rightly aborts the run, the host's verdict, not the bench's (tests/host_lag.py)
    with lag.judged(0.3):
        assert code == 0 and "run complete" in capsys.readouterr().out
        with h5py.File(out, "r") as f:
            assert f.attrs["status"] == "complete" and "DAQ970A" in f.attrs["idn"]
            scans = f["raw/instrument/time"][:]  # run time of each scan, every 0.2 s period
            duration = len(f["aligned/time"]) * 0.01
            # scans throughout the run (a loaded machine's stalls of a second, 2 s of run time, may cost a few)
            assert len(scans) > 0.5 * duration / 0.2 and scans[-1] > duration - 5.0
            assert np.nanmedian(f["aligned/T_air"][:]) == pytest.approx(40.0, abs=0.01)  # the socket instrument's
            flywheel = f["aligned/T_flywheel"][:]
            flywheel = flywheel[np.isfinite(flywheel)]
            assert flywheel.max() - flywheel[0] > 0.5  # the simulated node sees the launch heat the flywheel
    log = (tmp_path / "run.log").read_text()
    assert "SCPI > READ?" in log and "drivers.visa_port" in log and "flush" in log


@pytest.mark.parametrize("case", ["missing port", "unknown interface", "missing driver library", "wrong bitrate",
                                  "refused socket"])
def test_every_device_open_failure_is_one_line_naming_the_key(case, tmp_path, capsys) -> None:
    instrument, can_table, key = "sim://fail-dmm", 'url = "sim://fail-can"', "[can]"
    if case == "missing port":
        instrument, key, why = "/dev/ttyUSB-benchlab-none", "[instrument] url", "no such device"
    elif case == "refused socket":
        instrument, key, why = "TCPIP0::127.0.0.1::1::SOCKET", "[instrument] url", "connection refused"
    elif case == "unknown interface":
        can_table, key, why = 'interface = "nosuch"\nchannel = "x"', "[can] interface", "python-can's interfaces:"
    elif case == "missing driver library":
        can_table, why = 'interface = "kvaser"\nchannel = 0', "vendor library is not installed"
    else:
        can_table, why = 'interface = "slcan"\nchannel = "loop://"\nbitrate = 123456', "Invalid bitrate"
    bench = _bench(tmp_path, instrument, "sim://fail-node", can_table)
    code = main(["run", "table1", "--bench", str(bench), "--cycles", "1", "--out", str(tmp_path / "r.h5")])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.err.count("\n") == 1, captured.err  # no backend warning, no traceback
    assert captured.err.startswith(f"benchlab run: {bench}: {key}: ") and why in captured.err
    assert "here" in captured.err or "interfaces" in captured.err  # what exists instead
    assert not (tmp_path / "r.h5").exists()


def test_a_missing_backend_library_says_nothing_else_without_v(tmp_path) -> None:
    """In a fresh process (python-can warns when it first imports a backend): one line, exit 2; with -v the
    backend's own warning is shown too."""
    argv = [sys.executable, "-m", "benchlab.cli", "probe", "can", "--url", "kvaser:0"]
    quiet = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert quiet.returncode == 2 and quiet.stderr.count("\n") == 1, quiet.stderr
    assert quiet.stderr.startswith("benchlab probe: command line: --url: interface='kvaser'")
    loud = subprocess.run(argv[:3] + ["-v"] + argv[3:], capture_output=True, text=True, timeout=120)
    assert loud.returncode == 2 and "WARNING can.kvaser" in loud.stderr


def test_can_url_is_only_sim(tmp_path, capsys) -> None:
    bench = _bench(tmp_path, "sim://x", "sim://y", 'url = "virtual:rig"')
    assert main(["probe", "--bench", str(bench)]) == 2
    assert capsys.readouterr().err == f"benchlab probe: {bench}: can.url: sim://NAME (the emulated controllers), " \
        "got 'virtual:rig'; hardware is given by python-can's keys (interface, channel, bitrate)\n"


def test_probe_bench_reports_every_device(tmp_path, capsys) -> None:
    bench = _bench(tmp_path, "/dev/ttyUSB-benchlab-none", "sim://probe-node", 'url = "sim://probe-can"')
    with HostLag() as lag:
        code = main(["probe", "--bench", str(bench), "--timeout", "5"])
    assert code == 2  # the scanner does not open
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) == 4 and "Stats(" not in out, out  # a verdict per device and the bench's, no frame dumps
    assert lines[0].startswith(f"pt1000  FAILED   {bench}: [instrument] url: '/dev/ttyUSB-benchlab-none' did not "
                               "open")
    assert lines[1].startswith("node    ") and "sim://probe-node: " in lines[1]  # still probed after the failure
    with lag.judged(0.3):  # the emulated controllers send on the wall clock: a host that kept them from a core
        assert lines[2].split()[:2] in (["can", "OK"], ["can", "WARN"]) and "from clutch, drive, load" in lines[2]
    assert lines[3] == f"{bench}: {sum(' OK ' in line for line in lines[:3])} of 3 devices OK (-v: every reading and frame)"


def test_probe_can_talks_to_emulated_controllers(capsys) -> None:
    assert main(["probe", "can", "--url", "sim://bench", "--count", "6", "--json", "--timeout", "10"]) == 0
    import json

    doc = json.loads(capsys.readouterr().out)
    assert {s["controller"] for s in doc["samples"]} == {"drive", "clutch", "load"}
    assert doc["stats"]["sent"] == 0


def test_mixed_bench_runs_with_can_on_python_can_virtual(tmp_path, capsys) -> None:
    """Simulated scanner and node on one plant, the CAN bus python-can's virtual one with controllers on it (the
    hardware's stand-in, its own drivetrain on the wall clock): a short run on real time, the plant following the
    commands on the bus (the simulated node sees the launch's heat)."""
    from protocols.schedule import Step

    bench = _bench(tmp_path, "sim://mixed-dmm", "sim://mixed-node", 'interface = "virtual"\nchannel = "mixed-rig"')
    controllers_bus = can.Bus(interface="virtual", channel="mixed-rig")
    controllers = CanBenchEmulator(controllers_bus, clock=time.time)
    steps = (Step("open", 1.0, 800.0, 0.0, 0.0, 0), Step("launch", 2.0, 1000.0, 30.0, 100.0, 0),
             Step("open", 1.0, 1000.0, 0.0, 0.0, 0))
    out = tmp_path / "mixed.h5"
    try:
        with HostLag() as lag, RealtimeLoop(controllers.poll, period_s=0.002):
            code, summary = session.execute(session.RunRequest("table1", out, bench=str(bench), steps=steps,
                                                               install_signals=False))
    finally:
        controllers_bus.shutdown()
    # the controllers' drivetrain runs on the wall clock: where the host kept its thread from a core longer than the
    # steps' margin, the speeds are the host's verdict, not the bench's (tests/host_lag.py)
    with lag.judged(0.3):
        assert code == 0 and summary.status == "complete", summary.lines()
        with h5py.File(out, "r") as f:
            assert f.attrs["bench"] == str(bench)
            assert np.nanmax(f["aligned/engine_speed"][:]) > 900.0  # the controllers on the bus followed the steps
            flywheel = f["aligned/T_flywheel"][:]
            flywheel = flywheel[np.isfinite(flywheel)]
            rise = flywheel.max() - flywheel[0]
        assert rise > 0.2, rise  # the plant's launch (sensor noise: 0.05 K)


def test_a_partly_simulated_bench_names_its_simulated_devices(tmp_path, capsys) -> None:
    from benchlab.provenance import bench_text
    from benchlab.runner.config import load_bench_config
    from benchlab.runner.opening import simulated_devices

    bench = _bench(tmp_path, "TCPIP0::127.0.0.1::5025::SOCKET", "sim://rig-node", 'url = "sim://rig-can"')
    named = simulated_devices(load_bench_config(bench))
    assert named == "node sim://rig-node, CAN sim://rig-can"
    assert bench_text(str(bench), simulated=named) == f"the hardware bench {bench} (simulated: {named})"
    assert main(["run", "table1", "--bench", str(bench), "--dry-run", "--cycles", "1"]) == 0
    assert f"(simulated: {named})" in capsys.readouterr().out
    hardware = _bench(tmp_path, "TCPIP0::127.0.0.1::5025::SOCKET", "socket://127.0.0.1:9",
                      'interface = "virtual"\nchannel = "rig"',
                      name="hardware.toml")
    assert simulated_devices(load_bench_config(hardware)) == ""
