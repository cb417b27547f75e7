"""Decode-and-store throughput on one core, beside the physical limits of the links.

CAN: 1 Mbit/s saturated with 8-byte frames ≈ 8,000 frames/s. Gateway: 921,600 baud 8N1 = 92,160 B/s, i.e.
3,840 frames/s of our 24-byte frames (3,072 for 30-byte frames). Target: ≥ 10× each limit.
Run: .venv/bin/python benchmarks/bench_decode.py [--frames N]
"""

from __future__ import annotations

import argparse
import time
from array import array
from collections.abc import Callable

import can
import cantools
import numpy as np

from drivers import can_signals as sig
from drivers import node_frame
from drivers.can_bench import CanBench
from drivers.can_codec import MessageCodec
from drivers.clutch_node import ClutchNodeGateway

CAN_LIMIT = 8_000
SERIAL_LIMIT = 921_600 / 10 / (node_frame.ENCODED_LEN + 1)
STATUS = ("DriveMotor_Status", "ClutchActuator_Status", "LoadMachine_Status")


def can_frames(db: cantools.database.Database, n: int) -> list[can.Message]:
    """Status frames of the three controllers, round robin, with random payloads and proper alive counters."""
    rng = np.random.default_rng(0)
    messages = [db.get_message_by_name(name) for name in STATUS]
    frames = []
    for i in range(n):
        m = messages[i % 3]
        payload = bytearray(rng.integers(0, 256, m.length, dtype=np.uint8).tobytes())
        payload[7] = (payload[7] & 0x0F) | (((i // 3 + 1) % 16) << 4)
        frames.append(can.Message(arbitration_id=m.frame_id, data=bytes(payload), is_extended_id=False))
    return frames


def timed(label: str, n: int, limit: float, run: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    run()
    rate = n / (time.perf_counter() - t0)
    print(f"  {label:44s} {rate:>11,.0f} frames/s   {rate / limit:6.1f}× the link limit")
    return rate


def bench_can(n: int) -> None:
    db = cantools.database.load_file(str(sig.BENCH_DBC))
    frames = can_frames(db, n)
    print(f"CAN ({n:,} status frames; limit {CAN_LIMIT:,} frames/s at 1 Mbit/s)")

    def with_cantools() -> None:
        store: dict[str, array] = {}
        for msg in frames:
            for name, value in db.decode_message(msg.arbitration_id, msg.data, decode_choices=False).items():
                store.setdefault(name, array("d")).append(value)

    codecs = {db.get_message_by_name(name).frame_id: MessageCodec(db.get_message_by_name(name)) for name in STATUS}

    def with_codec() -> None:
        store: dict[str, array] = {}
        for msg in frames:
            for name, value in codecs[msg.arbitration_id].decode(msg.data).items():
                store.setdefault(name, array("d")).append(value)

    bench = CanBench(can.Bus(interface="virtual", channel="bench-decode"), listen_only=True)

    def with_driver() -> None:
        store: dict[str, array] = {}
        handle = bench.handle
        for msg in frames:
            sample = handle(msg, 0.0)
            for key, value in sample.values.items():
                store.setdefault(key, array("d")).append(value)

    def raw_then_vectorised() -> None:
        raw = {ident: bytearray() for ident in codecs}
        for msg in frames:
            raw[msg.arbitration_id] += msg.data
        for ident, buf in raw.items():
            codecs[ident].decode_array(np.frombuffer(bytes(buf), dtype=np.uint8).reshape(-1, 8))

    timed("cantools decode + array append", n, CAN_LIMIT, with_cantools)
    timed("compiled codec decode + array append", n, CAN_LIMIT, with_codec)
    timed("CanBench.handle (watchdog, alive) + append", n, CAN_LIMIT, with_driver)
    timed("store raw, numpy-vectorised decode", n, CAN_LIMIT, raw_then_vectorised)
    assert bench.stats.frames_ok == n and bench.stats.alive_errors == 0
    bench.close()


def bench_gateway(n: int) -> None:
    stream = b"".join(node_frame.encode(node_frame.NodeFrame(i & 0xFFFF, i * 50, (1_097_347 + i % 1000, 1_385_055),
                                                             5000, -60, 200)) for i in range(n))
    print(f"Gateway ({n:,} frames, {len(stream):,} bytes; limit {SERIAL_LIMIT:,.0f} frames/s at 921,600 baud)")

    def parse_only() -> None:
        for chunk in stream.split(node_frame.DELIMITER)[:-1]:
            node_frame.decode(chunk)

    def driver_and_store() -> None:
        gateway = ClutchNodeGateway(None, clock=lambda: 0.0)
        r1, t1, seq = array("d"), array("d"), array("l")
        for start in range(0, len(stream), 4096):
            for s in gateway.feed(stream[start:start + 4096]):
                seq.append(s.seq)
                r1.append(s.resistance_ohm[0])
                t1.append(s.temperature_c[0])
        assert gateway.stats.frames_ok == n and gateway.stats.lost == 0 and len(seq) == n

    timed("COBS + CRC + unpack", n, SERIAL_LIMIT, parse_only)
    timed("ClutchNodeGateway.feed (+CVD, seq) + append", n, SERIAL_LIMIT, driver_and_store)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200_000)
    args = parser.parse_args()
    bench_can(args.frames)
    bench_gateway(args.frames)


if __name__ == "__main__":
    main()
