"""A hardware bench some of whose devices are simulated: the `sim://NAME` devices of BENCH.toml, one plant behind them.

`[instrument] url = "sim://NAME"` and `[node] url = "sim://NAME"` reach the scanning DMM and the node of one
`SimBench` (registered under NAME), `[can] url = "sim://NAME"` its emulated controllers; every simulated device is
driven by that bench's plant and runs on the run's clock (real time: the hardware beside it sets the pace). With
the CAN bus on hardware the plant sees no set-points (its drivetrain stays at rest) and its sensors read the
temperatures of a bench at rest.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from sim_bench.bench import SimBench, SimBenchConfig
from sim_bench.emulators import registry

if TYPE_CHECKING:
    from benchlab.runner.devices import BenchConfig

log = logging.getLogger(__name__)
SIM = "sim://"


def simulated_urls(config: "BenchConfig") -> dict[str, str]:
    """The devices of `config` given as `sim://NAME`: key ("instrument", "node", "can") -> URL."""
    urls = {"instrument": config.instrument_url, "node": config.node_url, "can": config.can.get("url", "")}
    return {key: url for key, url in urls.items() if isinstance(url, str) and url.startswith(SIM)}


class SimulatedDevices:
    """The simulated devices of a partly simulated bench: one SimBench on the run's clock, registered under the
    BENCH.toml's names; `config` is the bench's configuration with the CAN bus the drivers use."""

    def __init__(self, config: "BenchConfig", clock: Callable[[], float], seed: int, t0: float = 0.0,
                 initial_c: float | Mapping[str, float] | None = None) -> None:
        urls = simulated_urls(config)
        cfg = SimBenchConfig(seed=seed, dt=config.dt, t0=t0, drivetrain=config.drivetrain, initial_c=initial_c,
                             node_period_s=config.node_period_s, dmm_channels=dict(config.instrument_channels))
        self.sim = SimBench(cfg, clock=clock)  # type: ignore[arg-type] - any () -> seconds clock
        self.names: list[str] = []
        for key, endpoint in (("instrument", self.sim.dmm), ("node", self.sim.node)):
            if key in urls:
                name = urls[key][len(SIM):].rstrip("/")
                registry.register(name, endpoint)
                self.names.append(name)
        self.bus: Any = None
        self.config = config
        if "can" in urls:  # the drivers on the emulated controllers' in-process bus, stamped on the run clock
            self.bus = self.sim.driver_bus
            self.config = replace(config, can={"url": urls["can"], "channel": self.sim.name + "-can"},
                                  can_timestamps="run")
        log.info("simulated devices on one plant: %s", ", ".join(f"{k} {u}" for k, u in urls.items()))

    def service(self) -> None:
        """Before the drivers poll: the emulators run up to now (SimBench.service)."""
        self.sim.service()

    def close(self) -> None:
        for name in self.names:
            registry.unregister(name)
        self.sim.close()

