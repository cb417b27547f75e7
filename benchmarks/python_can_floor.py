"""The per-frame floor of any stack that builds one python-can object per CAN frame, shared by the benchmarks that
set the simulated bench beside it (bench_sim_bench.py, bench_pipeline.py)."""

from __future__ import annotations

import time
from pathlib import Path


def python_can_floor_us(path: Path, n: int = 50_000) -> float:
    """CPU µs per frame that python-can itself costs: one can.Message built and written by its BLFWriter."""
    import can

    cpu0 = time.process_time()
    writer = can.Logger(str(path))
    for i in range(n):
        writer.on_message_received(can.Message(timestamp=i * 0.01, arbitration_id=0x111, data=bytes(8),
                                               is_extended_id=False))
    writer.stop()
    return (time.process_time() - cpu0) / n * 1e6
