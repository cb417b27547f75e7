"""Device emulators speaking the drivers' exact wire formats, driven by an injectable clock.

Importing this package registers the pyserial URL handler `sim://NAME` (protocol_sim.py) with two defaults:
`sim://instrument` (ScpiInstrumentEmulator) and `sim://node` (ClutchNodeEmulator), both on wall-clock time.
Register your own (e.g. on a ManualClock, fed by a thermal plant) with `registry.register(name, emulator)`.
"""

from __future__ import annotations

import serial

from sim_bench.emulators import registry
from sim_bench.emulators.can_controllers import CanBenchEmulator
from sim_bench.emulators.clock import ManualClock
from sim_bench.emulators.clutch_node import ClutchNodeEmulator
from sim_bench.emulators.drivetrain import DrivetrainActuals, DrivetrainProvider, FirstOrderDrivetrain
from sim_bench.emulators.providers import (ConstantNodeInputs, ConstantResistances, NodeInputProvider, NodeInputs,
                                           NodeInputSeries, ResistanceProvider, TemperatureResistances)
from sim_bench.emulators.realtime import RealtimeLoop
from sim_bench.emulators.scpi_instrument import ScpiInstrumentEmulator
from sim_bench.emulators.scripted_serial import ScriptedSerial
from sim_bench.emulators.sim_can_bus import SimCanBus

if __name__ not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(__name__)
registry.set_default("instrument", ScpiInstrumentEmulator)
registry.set_default("node", ClutchNodeEmulator)

__all__ = [
    "CanBenchEmulator", "ClutchNodeEmulator", "ConstantNodeInputs", "ConstantResistances", "DrivetrainActuals",
    "DrivetrainProvider", "FirstOrderDrivetrain", "ManualClock", "NodeInputProvider", "NodeInputs",
    "NodeInputSeries", "RealtimeLoop", "ResistanceProvider", "ScpiInstrumentEmulator", "ScriptedSerial", "SimCanBus",
    "TemperatureResistances",
    "registry",
]
