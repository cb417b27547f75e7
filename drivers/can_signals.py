"""Logical bench signal names → (DBC message, DBC signal): the only place the driver meets DBC names.

A vendor DBC replaces ours by passing another mapping with the same logical keys to CanBench.
"""

from __future__ import annotations

from pathlib import Path

BENCH_DBC = Path(__file__).with_name("bench.dbc")
CONTROLLERS = ("drive", "clutch", "load")

STATE_OFF, STATE_READY, STATE_RUNNING, STATE_FAULT, STATE_ESTOP = range(5)
CLAMP_OPEN, CLAMP_SLIPPING, CLAMP_CLAMPED = range(3)
FAULT_COMMAND_TIMEOUT = 16
ESTOP_SOURCE_PC = 0

SignalMap = dict[str, tuple[str, str]]

BENCH_SIGNALS: SignalMap = {
    # PC → controllers (sent cyclically by the driver)
    "drive.speed_setpoint": ("DriveMotor_Cmd", "DM_SpeedSetpoint"),
    "drive.enable": ("DriveMotor_Cmd", "DM_Enable"),
    "drive.cmd_alive": ("DriveMotor_Cmd", "DM_CmdAlive"),
    "clutch.torque_setpoint": ("ClutchActuator_Cmd", "CA_TorqueSetpoint"),
    "clutch.open_request": ("ClutchActuator_Cmd", "CA_OpenRequest"),
    "clutch.enable": ("ClutchActuator_Cmd", "CA_Enable"),
    "clutch.cmd_alive": ("ClutchActuator_Cmd", "CA_CmdAlive"),
    "load.torque_setpoint": ("LoadMachine_Cmd", "LM_TorqueSetpoint"),
    "load.enable": ("LoadMachine_Cmd", "LM_Enable"),
    "load.cmd_alive": ("LoadMachine_Cmd", "LM_CmdAlive"),
    "estop.request": ("EmergencyStop", "ES_Request"),
    "estop.source": ("EmergencyStop", "ES_Source"),
    "estop.alive": ("EmergencyStop", "ES_Alive"),
    "pc.hb_state": ("Heartbeat_PC", "PC_HbState"),
    "pc.hb_alive": ("Heartbeat_PC", "PC_HbAlive"),
    # controllers → PC (watched by the driver)
    "drive.speed": ("DriveMotor_Status", "DM_Speed"),
    "drive.torque": ("DriveMotor_Status", "DM_Torque"),
    "drive.state": ("DriveMotor_Status", "DM_State"),
    "drive.fault_code": ("DriveMotor_Status", "DM_FaultCode"),
    "drive.alive": ("DriveMotor_Status", "DM_Alive"),
    "drive.hb_state": ("Heartbeat_DriveMotor", "DM_HbState"),
    "drive.hb_alive": ("Heartbeat_DriveMotor", "DM_HbAlive"),
    "clutch.torque": ("ClutchActuator_Status", "CA_Torque"),
    "clutch.position": ("ClutchActuator_Status", "CA_Position"),
    "clutch.clamp_state": ("ClutchActuator_Status", "CA_ClampState"),
    "clutch.state": ("ClutchActuator_Status", "CA_State"),
    "clutch.fault_code": ("ClutchActuator_Status", "CA_FaultCode"),
    "clutch.alive": ("ClutchActuator_Status", "CA_Alive"),
    "clutch.hb_state": ("Heartbeat_ClutchActuator", "CA_HbState"),
    "clutch.hb_alive": ("Heartbeat_ClutchActuator", "CA_HbAlive"),
    "load.torque": ("LoadMachine_Status", "LM_Torque"),
    "load.speed": ("LoadMachine_Status", "LM_Speed"),
    "load.state": ("LoadMachine_Status", "LM_State"),
    "load.fault_code": ("LoadMachine_Status", "LM_FaultCode"),
    "load.alive": ("LoadMachine_Status", "LM_Alive"),
    "load.hb_state": ("Heartbeat_LoadMachine", "LM_HbState"),
    "load.hb_alive": ("Heartbeat_LoadMachine", "LM_HbAlive"),
}

TX_KEYS = frozenset({
    "drive.speed_setpoint", "drive.enable", "drive.cmd_alive",
    "clutch.torque_setpoint", "clutch.open_request", "clutch.enable", "clutch.cmd_alive",
    "load.torque_setpoint", "load.enable", "load.cmd_alive",
    "estop.request", "estop.source", "estop.alive", "pc.hb_state", "pc.hb_alive",
})


#: The run file's raw CAN streams: per stream its columns as (column, logical DBC signal key, unit).
CAN_STREAMS = {
    "can_drive": (("speed", "drive.speed", "rpm"), ("torque", "drive.torque", "N*m"),
                  ("state", "drive.state", "1"), ("fault_code", "drive.fault_code", "1")),
    "can_clutch": (("torque", "clutch.torque", "N*m"), ("position", "clutch.position", "mm"),
                   ("clamp_state", "clutch.clamp_state", "1"), ("state", "clutch.state", "1"),
                   ("fault_code", "clutch.fault_code", "1")),
    "can_load": (("torque", "load.torque", "N*m"), ("speed", "load.speed", "rpm"),
                 ("state", "load.state", "1"), ("fault_code", "load.fault_code", "1")),
}
#: The DBC signal (logical key of drivers.can_signals.BENCH_SIGNALS) each raw CAN column holds, by (stream, column):
#: what `benchlab export` gives the DBC's value tables from.
CAN_COLUMN_SIGNALS = {(stream, column): key for stream, cols in CAN_STREAMS.items() for column, key, _ in cols}
#: The /aligned channels taken from the CAN status streams: (channel, stream, column, times the gear ratio);
#: `_clamp_state` is the actuator's (derive_aligned makes clutch_state and friction_power of it).
CAN_ALIGNED = (("engine_speed", "can_drive", "speed", False), ("clutch_speed", "can_load", "speed", True),
               ("clutch_torque", "can_clutch", "torque", False), ("_clamp_state", "can_clutch", "clamp_state", False),
               ("load_torque", "can_load", "torque", False))
