"""The protocols `benchlab run` knows, by name: each builds its schedule (data) from seed and options.

The randomised schedules (numpy) load when built, so NAMES costs nothing (the command line's help lists them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from protocols.cooldown_sweep import DEFAULT_GRID, SweepConfig, cooldown_sweep_schedule, parse_grid
from protocols.schedule import Step

if TYPE_CHECKING:
    from protocols.limits import BenchLimits
    from protocols.estimates import Plant

NAMES = ("table1", "cooldown-sweep", "validation")
DEFAULT_TABLE1_DURATION_S = 7200.0
#: The channels each protocol holds at several values through long cool-downs (no heat source on): what a link's law
#: of those channels needs to be identified (benchlab.identify.excitation names the protocol).
COOLDOWNS_AT: dict[str, tuple[str, ...]] = {"cooldown-sweep": ("engine_speed", "clutch_state", "clutch_speed")}


@dataclass(frozen=True)
class Protocol:
    """A protocol's schedule for one bench, its options (stored with the run) and the plan's notes (draws left out)."""

    name: str
    steps: tuple[Step, ...]
    options: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()


def build(name: str, seed: int = 1, n_cycles: int | None = None, duration_s: float | None = None,
          grid: str | None = None, limits: "BenchLimits | None" = None, plant: "Plant | None" = None) -> Protocol:
    """The named protocol's schedule; ValueError for an unknown name or bad options.

    For a bench (`limits`): Table 1 draws whose launch cannot synchronise on its drivetrain are left out (each named
    in the notes and the options' "dropped"), and every launch is planned at its time to synchronise. `plant`: the
    thermal plant the run will use, on which a cool-down sweep's heat-ups and cool-downs are simulated for their
    expected durations (protocols.estimates.timed)."""
    if name == "table1":
        from protocols.table1 import table1_plan

        if n_cycles is None and duration_s is None:
            duration_s = DEFAULT_TABLE1_DURATION_S
        plan = table1_plan(seed, limits, n_cycles=n_cycles, duration_s=None if n_cycles is not None else duration_s)
        return _for_bench(Protocol(name, plan.steps, {"seed": seed, "cycles": n_cycles, "duration_s": duration_s},
                                   plan.dropped), limits)
    if name == "cooldown-sweep":
        points = parse_grid(grid) if grid else DEFAULT_GRID
        if n_cycles is not None:
            points = points[:n_cycles]
        return _for_bench(Protocol(name, cooldown_sweep_schedule(points, SweepConfig(), plant),
                                   {"grid": [list(p) for p in points], **SweepConfig().__dict__}), limits)
    if name == "validation":
        from protocols.validation import ValidationConfig, validation_plan

        cfg = ValidationConfig()
        plan = validation_plan(seed, cfg, n_cycles, limits)
        return _for_bench(Protocol(name, plan.steps, {"seed": seed, **cfg.__dict__}, plan.dropped), limits)
    raise ValueError(f"unknown protocol {name!r}: one of {', '.join(NAMES)}")


def _for_bench(protocol: Protocol, limits: "BenchLimits | None") -> Protocol:
    """The protocol with its launches timed on the bench's drivetrain and its dropped draws in the options."""
    if limits is None:
        return protocol
    from protocols.limits import with_launch_estimates

    options = {**protocol.options, "dropped": list(protocol.notes)} if protocol.notes else protocol.options
    return Protocol(protocol.name, with_launch_estimates(protocol.steps, limits), options, protocol.notes)
