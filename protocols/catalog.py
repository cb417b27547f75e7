"""The protocols `benchlab run` knows, by name: each builds its schedule (data) from seed and options.

The randomised schedules (numpy) load when built, so NAMES costs nothing (the command line's help lists them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocols.cooldown_sweep import DEFAULT_GRID, SweepConfig, cooldown_sweep_schedule, parse_grid
from protocols.schedule import Step

NAMES = ("table1", "cooldown-sweep", "validation")
DEFAULT_TABLE1_DURATION_S = 7200.0


@dataclass(frozen=True)
class Protocol:
    name: str
    steps: tuple[Step, ...]
    options: dict[str, Any] = field(default_factory=dict)


def build(name: str, seed: int = 1, n_cycles: int | None = None, duration_s: float | None = None,
          grid: str | None = None) -> Protocol:
    """The named protocol's schedule; ValueError for an unknown name or bad options."""
    if name == "table1":
        from protocols.table1 import table1_schedule

        if n_cycles is None and duration_s is None:
            duration_s = DEFAULT_TABLE1_DURATION_S
        steps = table1_schedule(seed, n_cycles=n_cycles, duration_s=None if n_cycles is not None else duration_s)
        return Protocol(name, steps, {"seed": seed, "cycles": n_cycles, "duration_s": duration_s})
    if name == "cooldown-sweep":
        points = parse_grid(grid) if grid else DEFAULT_GRID
        if n_cycles is not None:
            points = points[:n_cycles]
        return Protocol(name, cooldown_sweep_schedule(points, SweepConfig()),
                        {"grid": [list(p) for p in points], **SweepConfig().__dict__})
    if name == "validation":
        from protocols.validation import ValidationConfig, validation_schedule

        cfg = ValidationConfig()
        return Protocol(name, validation_schedule(seed, cfg, n_cycles), {"seed": seed, **cfg.__dict__})
    raise ValueError(f"unknown protocol {name!r}: one of {', '.join(NAMES)}")
