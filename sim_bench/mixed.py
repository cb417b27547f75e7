"""A hardware bench some of whose devices are simulated: the `sim://NAME` devices of BENCH.toml, one plant behind them.

`[instrument] url = "sim://NAME"` and `[node] url = "sim://NAME"` reach the scanning DMM and the node of one
`SimBench` (registered under NAME), `[can] url = "sim://NAME"` its emulated controllers; every simulated device is
driven by that bench's plant and runs on the run's clock (real time: the hardware beside it sets the pace). With
the CAN bus on hardware, the frames on it are copied to the emulated controllers through a second handle on the
same bus (python-can `virtual`, socketcan and most interfaces allow one), so the plant's drivetrain follows the
commands the PC sends and the simulated sensors see the heat of the launches; where no second handle opens, the
plant stays at rest.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from sim_bench.bench import SimBench, SimBenchConfig
from sim_bench.emulators import registry
from sim_bench.emulators.sim_can_bus import SimCanBus

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
        self._mirror: Any = None  # hardware CAN: a second handle on it, whose frames the emulated controllers take
        if "can" in urls:  # the drivers on the emulated controllers' in-process bus, stamped on the run clock
            self.sim.driver_bus.shutdown()  # replaced by one that runs the controllers up to each receive
            self.bus = _ControllersSendUntilRead(self.sim.name + "-can", clock=clock, before=self.sim.can.poll)
            self.config = replace(config, can={"url": urls["can"], "channel": self.sim.name + "-can"},
                                  can_timestamps="run")
        else:
            self._mirror = _second_handle(config.can)
        log.info("simulated devices on one plant: %s", ", ".join(f"{k} {u}" for k, u in urls.items()))

    def service(self) -> None:
        """Before the drivers poll: the frames on a hardware bus copied to the emulated controllers (on the run
        clock), the emulators run up to now (SimBench.service), their answers dropped (the hardware answers)."""
        if self._mirror is not None:
            while (msg := self._mirror.recv(0)) is not None:
                msg.timestamp = 0.0  # taken now, on the run clock
                self.sim.driver_bus.send(msg)
        self.sim.service()
        if self._mirror is not None:
            self.sim.driver_bus.recv_frames()

    def close(self) -> None:
        for name in self.names:
            registry.unregister(name)
        if self._mirror is not None:
            self._mirror.shutdown()
        self.sim.close()


class _ControllersSendUntilRead(SimCanBus):
    """The drivers' end of the emulated controllers' bus: each receive first lets the controllers send what fell
    due up to that moment. On the real clock the time between a poll's emulation and the drivers' receive (the
    other devices' polls, a stall of a loaded machine) would otherwise read as a silent controller; hardware
    controllers keep sending while the PC is busy."""

    def __init__(self, channel: str, *, clock: Callable[[], float], before: Callable[[], None]) -> None:
        super().__init__(channel, clock=clock)
        self._before = before

    def recv_frames(self) -> Any:
        self._before()
        return super().recv_frames()


def _second_handle(can_config: Mapping[str, Any]) -> Any:
    """A second python-can handle on the hardware bus, or None (logged) where the interface allows none."""
    import can

    try:
        return can.Bus(**dict(can_config))
    except Exception as exc:  # noqa: BLE001 - the drivers' own open says what is wrong with the bus
        log.info("no second handle on the CAN bus (%s): the simulated plant stays at rest", exc)
        return None

