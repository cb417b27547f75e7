"""`python -m sim_bench.emulators.scpi_server` (docs/hardware.md): the SCPI emulator served on 127.0.0.1 from the
command line, answering `*IDN?` at the resource it prints (issue 46)."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys


def test_the_server_command_serves_the_emulator_at_the_resource_it_prints():
    proc = subprocess.Popen([sys.executable, "-m", "sim_bench.emulators.scpi_server", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        match = re.search(r"TCPIP0::127\.0\.0\.1::(\d+)::SOCKET", line)
        assert match, line + proc.stderr.read() if proc.poll() is not None else line
        with socket.create_connection(("127.0.0.1", int(match[1])), timeout=10) as client:
            client.sendall(b"*IDN?\n")
            reply = b""
            while not reply.endswith(b"\n"):
                reply += client.recv(4096)
        assert reply.count(b",") == 3  # maker, model, serial, firmware
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0


def test_the_server_refuses_a_port_out_of_range():
    done = subprocess.run([sys.executable, "-m", "sim_bench.emulators.scpi_server", "--port", "70000"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "--port" in done.stderr and "Traceback" not in done.stderr
