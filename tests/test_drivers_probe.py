"""`benchlab probe` against the emulators: output, JSON, exit codes."""

import json

import can
import pytest

from benchlab.cli import main
from sim_bench.emulators import CanBenchEmulator, RealtimeLoop


def test_probe_pt1000_text(capsys) -> None:
    assert main(["probe", "pt1000", "--url", "sim://instrument"]) == 0
    out = capsys.readouterr().out
    assert "DAQ970A" in out and out.count("°C") == 4


def test_probe_pt1000_json(capsys) -> None:
    assert main(["probe", "pt1000", "--url", "sim://instrument", "--json", "--count", "2", "--mode", "frtd",
                 "--channels", "(@101,102)"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["channel"] for r in doc["readings"]] == [101, 102, 101, 102]
    assert all(r["status"] == "ok" and r["temperature_c"] == pytest.approx(25.0, abs=1e-3) for r in doc["readings"])


def test_probe_node_json(capsys) -> None:
    # a time-out far above the 50 ms frame period: the probe ends at the 3rd frame, and a fresh clone compiles the
    # node decoder on its first frames (numba), inside the probe's real-time wait (failed once with the 2 s default)
    assert main(["probe", "node", "--url", "sim://node", "--count", "3", "--json", "--timeout", "30"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["samples"]) >= 3 and doc["stats"]["crc_errors"] == 0


def test_probe_can_against_running_emulator(capsys) -> None:
    bus = can.Bus(interface="virtual", channel="probe-test")
    emu = CanBenchEmulator(bus)
    try:
        with RealtimeLoop(emu.poll, period_s=0.002):
            # a time-out far above the frames' 10 ms: the probe ends at the 8th frame, and a loaded machine (two
            # test processes on two cores) may starve the emulator's thread for a while (failed once with 2 s)
            argv = ["probe", "can", "--url", "virtual:probe-test", "--count", "8", "--json", "--timeout", "30"]
            assert main(argv) == 0
    finally:
        bus.shutdown()
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["samples"]) >= 8 and {s["controller"] for s in doc["samples"]} == {"drive", "clutch", "load"}
    assert doc["stats"]["sent"] == 0  # probing never commands the bench


def test_probe_can_nothing_there_exits_1(capsys) -> None:
    assert main(["probe", "can", "--url", "virtual:nobody-here", "--timeout", "0.1"]) == 1
    assert "silent" in capsys.readouterr().out


def test_probe_can_passes_the_bitrate_to_the_bus(monkeypatch, capsys) -> None:
    opened = []

    def bus(**config):
        opened.append(config)
        return can.interface.Bus(**config)

    monkeypatch.setattr(can, "Bus", bus)
    assert main(["probe", "can", "--url", "virtual:bitrate-test", "--bitrate", "250000", "--timeout", "0.1"]) == 1
    assert opened == [{"interface": "virtual", "channel": "bitrate-test", "bitrate": 250000}]
    assert main(["probe", "can", "--url", "virtual:bitrate-test", "--timeout", "0.1"]) == 1
    assert "bitrate" not in opened[1]  # not given: the interface's own default


@pytest.mark.parametrize("argv", [
    ["probe", "can", "--url", "virtual:x", "--bitrate", "fast"],
    ["probe", "can", "--url", "virtual:x", "--bitrate", "0"],
    ["probe", "can", "--url", "virtual:x", "--bitrate", "8000000"],
    ["probe", "node", "--url", "sim://node", "--bitrate", "500000"],
    ["probe", "pt1000", "--url", "nonsense://x"],
    ["probe", "pt1000", "--url", "/dev/does-not-exist-benchlab"],
    ["probe", "pt1000", "--url", "sim://no-such-emulator"],
    ["probe", "pt1000", "--url", "sim://instrument", "--channels", "101-104"],
    ["probe", "node", "--url", "nonsense://x"],
    ["probe", "node", "--url", "sim://node", "--count", "0"],
    ["probe", "can", "--url", "can0"],
    ["probe", "can", "--url", "nosuchinterface:can0"],
    ["probe", "can", "--url", "udp_multicast:239.0.0.1"],
    ["probe", "can", "--url", "socketcan:benchlab-none"],  # no such interface (or no CAN in the kernel)
    ["probe", "can", "--url", "kvaser:0"],  # python-can's backend without its vendor library: NameError inside
    ["probe", "pt1000", "--url", "TCPIP0::127.0.0.1::1::SOCKET"],  # a VISA socket nobody listens on
    ["probe", "--bench", "no-such-bench.toml"],
    ["probe", "pt1000"],  # neither --url nor --bench
])
def test_probe_bad_input_exits_2(argv: list[str], capsys) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:  # --channels and --count are refused by argparse, at parse time
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("benchlab probe: ") and err.count("\n") == 1
