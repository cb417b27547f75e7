"""A scan of the PT1000 scanner the way the acquisition loop does it (start_scan, then collect until done: READ?
and SYST:ERR?), through a VISA TCPIP SOCKET resource (pyvisa-py, replies read by drivers/visa_port.py's thread)
beside its peer, the same emulator over pyserial's socket:// (no thread), both on loopback.

Per scan: wall time from READ? to the readings, and the loop thread's CPU time (what polling costs the loop that
also keeps CAN frames cyclic). The scan period is 0.2 s: a scan must take a small part of it.
Run: .venv/bin/python benchmarks/bench_scan.py [--scans N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from drivers.pt1000 import Pt1000Scanner
from sim_bench.emulators import ScpiInstrumentEmulator
from sim_bench.emulators.scpi_server import ScpiSocketServer

PERIOD_S = 0.2


def scans(url: str, n: int, poll_s: float) -> tuple[list[float], list[float]]:
    """n scans polled every `poll_s`: (wall s, loop-thread CPU s) per scan."""
    scanner = Pt1000Scanner.open(url, [101, 102, 103], timeout=2.0)
    scanner.identify()
    scanner.reset()
    wall, cpu = [], []
    try:
        for _ in range(n):
            t0, c0 = time.perf_counter(), time.thread_time()
            scanner.start_scan()
            while scanner.collect() is None:
                time.sleep(poll_s)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
    finally:
        scanner.close()
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=300)
    parser.add_argument("--poll-ms", type=float, default=1.0, help="the loop's sleep between collects")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; {args.scans} scans each, polled every {args.poll_ms} ms")
    with ScpiSocketServer(ScpiInstrumentEmulator()) as server:
        results = {}
        for label, url in (("VISA TCPIP SOCKET (pyvisa-py)", server.resource),
                           ("pyserial socket:// (peer)", f"socket://127.0.0.1:{server.port}")):
            wall, cpu = scans(url, args.scans, args.poll_ms / 1000)
            results[label] = (statistics.median(wall), max(wall), statistics.median(cpu))
            print(f"  {label:32s} wall median {results[label][0] * 1e3:6.2f} ms, max {results[label][1] * 1e3:6.1f}"
                  f" ms; loop CPU median {results[label][2] * 1e3:6.3f} ms per scan "
                  f"({results[label][0] / PERIOD_S:.1%} of the scan period)")
    (visa, peer) = results.values()
    print(f"VISA / peer: wall {visa[0] / peer[0]:.2f}x, loop CPU {visa[2] / peer[2]:.2f}x; "
          f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
