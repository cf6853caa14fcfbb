"""The CANopen device profile's wire values: which object carries which quantity, and in which
step (the DBC's own resolution for the same quantity, so both profiles quantise alike).

- CiA 408 valve: control word 0x6040 (bit 0 D: power stage on, 1 H: hold, 2 M: device mode
  active, 3 R: reset fault on its rising edge), status word 0x6041 (D, H, M as the device
  state has them; bit 3 ready: no fault), spool setpoint 0x6300:1 and actual 0x6301:1 in
  0x6311's increments (16384 = 100 % of the valve's input).
- CiA 406 encoder: position value 0x6004 in counts of the DBC's POSITION step, from the
  leg's shortest stroke.
- CiA 404 measuring devices (AI input process values 0x7130, INTEGER16): a leg's load cell
  (channel 1) and chamber A, chamber B and supply pressures (2-4); the IMU's roll, pitch,
  yaw (1-3) and rates about x, y, z (4-6). Each in the DBC's step for it: a value beyond
  INTEGER16 saturates there (pressures at 327 bar, forces at 3277 N).
"""

from __future__ import annotations

from protocol.codec import UNIT_TO_SI
from protocol.dbc import signal_scale
from protocol.enums import ValveState

CONTROL_WORD, STATUS_WORD = (0x6040, 0), (0x6041, 0)
SPOOL_SETPOINT, SPOOL_ACTUAL = (0x6300, 1), (0x6301, 1)
POSITION = (0x6004, 0)
AI_PV = 0x7130
LEG_FORCE, LEG_PA, LEG_PB, LEG_PS = ((AI_PV, k) for k in range(1, 5))
IMU_ATTITUDE = tuple((AI_PV, k) for k in range(1, 4))
IMU_RATE = tuple((AI_PV, k) for k in range(4, 7))

BIT_D, BIT_H, BIT_M, BIT_R = 0x1, 0x2, 0x4, 0x8
STATUS_READY = 0x8
SPOOL_FULL_SCALE = round(100.0 / signal_scale("VALVE_CMD_1", "SPOOL_SETPOINT"))     # 16384
STATUS_OF_STATE = {ValveState.INIT: 0, ValveState.DISABLED: STATUS_READY,
                   ValveState.HOLD: BIT_D | BIT_H | STATUS_READY,
                   ValveState.ACTIVE: BIT_D | BIT_H | BIT_M | STATUS_READY,
                   ValveState.FAULT_HOLD: BIT_D | BIT_H, ValveState.FAULT_DISABLED: 0}


def _step(message: str, signal: str, unit: str) -> float:
    return signal_scale(message, signal) * UNIT_TO_SI[unit]


POSITION_STEP_M = _step("LEG_STATE_1", "POSITION", "mm")
FORCE_STEP_N = _step("LEG_STATE_1", "FORCE", "N")
PRESSURE_STEP_PA = _step("LEG_PRESSURE_1", "PA", "bar")
ANGLE_STEP_RAD = _step("IMU_ATTITUDE", "ROLL", "rad")
RATE_STEP_RAD_S = _step("IMU_RATE", "RATE_X", "rad/s")


def control_bits(word: int) -> tuple[bool, bool, bool, bool]:
    """A control word's (D, H, M, R)."""
    return bool(word & BIT_D), bool(word & BIT_H), bool(word & BIT_M), bool(word & BIT_R)


def control_word(d: bool, h: bool, m: bool, r: bool) -> int:
    return BIT_D * d | BIT_H * h | BIT_M * m | BIT_R * r


def status_word(state: ValveState) -> int:
    return STATUS_OF_STATE[ValveState(state)]


def counts(value_si: float, step_si: float) -> int:
    """A quantity in its object's counts (the codec saturates it at the object's type)."""
    return round(value_si / step_si)


STATE_OF_STATUS = {word: state for state, word in STATUS_OF_STATE.items() if state != ValveState.INIT}


def valve_state(word: int) -> ValveState:
    """The CiA 408 state a status word reports (bits D, H, M and ready; 0: a fault with the
    power stage off, since a device sends no TPDO before it is started)."""
    return STATE_OF_STATUS.get(word & (BIT_D | BIT_H | BIT_M | STATUS_READY), ValveState.FAULT_DISABLED)


# what a leg's devices measure, by object: (the quantity, SI per count); the IMU's by axis
LEG_MEASURED = {POSITION: ("position", POSITION_STEP_M), LEG_FORCE: ("force", FORCE_STEP_N),
                SPOOL_ACTUAL: ("spool", 1.0 / SPOOL_FULL_SCALE), STATUS_WORD: ("valve_state", 1.0),
                LEG_PA: ("pressure", PRESSURE_STEP_PA), LEG_PB: ("pressure", PRESSURE_STEP_PA),
                LEG_PS: ("pressure", PRESSURE_STEP_PA)}
LEG_PRESSURE_COLUMN = {LEG_PA: 0, LEG_PB: 1, LEG_PS: 2}      # PA, PB, PS as Measurements has them
# every cycle from each leg: what a LEG_STATE carries in the project's own profile
LEG_EVERY_CYCLE = ("position", "force", "valve_state", "spool")
