"""The closing lines every benchmark prints: each target with ok/MISSED, then one summary line with the load."""

from __future__ import annotations

import os
import time

Target = tuple[str, str, bool]  # name, measured vs target as text, reached


def load() -> str:
    """The machine's load, printed beside every timing: other processes share these 2 cores."""
    one, five, _ = os.getloadavg()
    return f"load avg {one:.2f} (1 min) {five:.2f} (5 min) on {os.cpu_count()} CPUs"


def print_target(name: str, text: str, ok: bool) -> None:
    """One target's line: name, measured vs target, ok or MISSED."""
    print(f"   {name:<30}{text:<28}{'ok' if ok else 'MISSED'}")


def summarise_targets(targets: list[Target], started: float) -> int:
    """The summary line (reached / all, the misses, run time, load); exit code 1 if any was missed."""
    missed = [t for t in targets if not t[2]]
    print(f"\nTARGETS: {len(targets) - len(missed)}/{len(targets)} reached"
          + ("" if not missed else "; missed: " + ", ".join(f"{name} ({text})" for name, text, _ in missed))
          + f"   [{time.perf_counter() - started:.0f} s, {load()}]")
    return 1 if missed else 0
