"""Every enumerated wire value, built at import from the DBC's value tables: the DBC is
their one home, and a value table edited there changes these enums with it.

A signal that several messages carry (VALVE_STATE of every leg, the heartbeats' STATE)
must have the same table in each; a difference fails at import.
"""

from __future__ import annotations

import math
from enum import IntEnum, IntFlag

from protocol.dbc import load_database


def value_table(message: str, signal: str) -> dict[int, str]:
    """{value: name} of a signal's value table in the DBC (KeyError when it has none)."""
    choices = load_database().get_message_by_name(message).get_signal_by_name(signal).choices
    if not choices:
        raise KeyError(f"{message}.{signal} has no value table in the DBC")
    return {int(value): str(name) for value, name in choices.items()}


def _same_table(messages: list[str], signal: str) -> dict[int, str]:
    tables = {message: value_table(message, signal) for message in messages}
    first = next(iter(tables.values()))
    differing = [m for m, table in tables.items() if table != first]
    if differing:
        raise ValueError(f"DBC: {signal} differs between {messages[0]} and {', '.join(differing)}")
    return first


def _enum(name: str, table: dict[int, str], kind=IntEnum):
    return kind(name, [(label, value) for value, label in sorted(table.items())])


def _messages(prefix: str) -> list[str]:
    return sorted(m.name for m in load_database().messages if m.name.startswith(prefix))


State = _enum("State", value_table("CTRL_STATUS", "STATE"))                 # the controller's state
Fault = _enum("Fault", value_table("CTRL_STATUS", "FAULT_CODE"))            # its latched fault
ControllerKind = _enum("ControllerKind", value_table("CTRL_STATUS", "CONTROLLER"))
Pacing = _enum("Pacing", value_table("CTRL_STATUS", "PACING"))               # what starts a cycle
Command = _enum("Command", value_table("HOST_CMD", "COMMAND"))              # HOST_CMD.COMMAND
Ack = _enum("Ack", value_table("CTRL_ACK", "RESULT"))                       # CTRL_ACK.RESULT
AckKind = _enum("AckKind", value_table("CTRL_ACK", "KIND"))                 # which host frame an ack answers
TestMode = _enum("TestMode", value_table("HOST_TEST", "MODE"))              # identification tests
WaypointFlag = _enum("WaypointFlag", value_table("HOST_WAYPOINT_TIME", "FLAGS"), IntFlag)
ValveState = _enum("ValveState", _same_table(_messages("LEG_STATE_") + _messages("VALVE_STATUS_"),
                                             "VALVE_STATE"))                # CiA 408 device states
ValveFaultReason = _enum("ValveFaultReason", _same_table(_messages("VALVE_STATUS_"), "FAULT_REASON"))
EmcyCode = _enum("EmcyCode", _same_table(_messages("EMCY_"), "ERROR_CODE"))  # CiA 301 emergency codes
SensorStatus = _enum("SensorStatus", _same_table(_messages("LEG_STATE_"), "SENSOR_FAULT"))
ImuStatus = _enum("ImuStatus", value_table("IMU_ATTITUDE", "STATUS"))
NmtCommand = _enum("NmtCommand", value_table("NMT", "COMMAND"))              # CiA 301 command specifiers
NmtState = _enum("NmtState", _same_table(_messages("HEARTBEAT_"), "STATE"))  # CiA 301 NMT states
EmuCommand = _enum("EmuCommand", value_table("EMU_CTRL", "COMMAND"))
EmuFault = _enum("EmuFault", value_table("EMU_CTRL", "FAULT"))               # faults the emulator injects
KickAxis = _enum("KickAxis", value_table("EMU_KICK", "AXIS"))                # EMU_KICK's push

PACINGS = tuple(p.name.lower() for p in Pacing)       # the command lines' --pacing
# who sends the SYNC ([timing] sync_source): the loop, the bus's periodic sender (SocketCAN: the
# kernel's broadcast manager), or auto (the bus on SocketCAN in realtime, else the loop)
SYNC_SOURCES = ("auto", "loop", "bus")

VALVE_FAULT_STATES = (ValveState.FAULT_HOLD, ValveState.FAULT_DISABLED)

# CTRL_ACK.TIME_SCALE beside RESULT BEYOND_CAPACITY: the factor that fits, rounded up to the
# signal's 0.01; its largest value says that none does, 0 that it does not apply
TIME_SCALE_STEP, TIME_SCALE_NONE_FITS = 0.01, 655.35


def time_scale_to_wire(scale: float) -> float:
    """NaN (not applicable) -> 0; inf or beyond the signal -> TIME_SCALE_NONE_FITS."""
    if math.isnan(scale):
        return 0.0
    if not scale < TIME_SCALE_NONE_FITS:
        return TIME_SCALE_NONE_FITS
    return math.ceil(round(scale / TIME_SCALE_STEP, 6)) * TIME_SCALE_STEP


def time_scale_from_wire(value: float) -> float:
    """The inverse: 0 -> NaN, TIME_SCALE_NONE_FITS -> inf."""
    if value <= 0.0:
        return math.nan
    return math.inf if value >= TIME_SCALE_NONE_FITS - TIME_SCALE_STEP / 2 else value
TestMode.__test__ = False            # an enum, not a pytest class despite its name
