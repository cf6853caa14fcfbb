"""The typed hand-offs between the rig and the controller: what was read this cycle
(`Measurements`, the state interfaces) and what the controller commands (`ValveCommands`,
the command interfaces), and where each of their fields sits in the DBC's frames. Both are
allocated once; a cycle only writes into them. The controller's loop fills them from the
bus; a simulated rig (plant_emulator/simulated_rig.py) fills them in process.
"""

from __future__ import annotations

import numpy as np

from protocol.codec import CODECS
from protocol.enums import ImuStatus


class Measurements:
    """One cycle's inputs, SI. The loop (or a simulated rig) fills it and decides nothing;
    `Controller.update` reads it. Node events are the ones seen since the previous cycle's read."""

    def __init__(self, n_legs: int, n_nodes: int):
        # LEG_STATE_n, every cycle
        self.position_m = np.zeros(n_legs)             # encoder stroke from the retracted end
        self.force_n = np.zeros(n_legs)                # load cell, + = the rod pushes the load
        self.valve_state = np.zeros(n_legs, dtype=np.int64)   # CiA 408 state the valve reported
        self.sensor_fault = np.zeros(n_legs, dtype=bool)
        self.spool = np.zeros(n_legs)                  # the valve's actual spool, fraction of full input
        self.fresh = np.zeros(n_legs, dtype=bool)      # a valid LEG_STATE arrived this cycle
        self.rejected = np.zeros(n_legs, dtype=bool)   # a LEG_STATE failed the E2E check this cycle
        # LEG_PRESSURE_n, every 16th cycle: the latest valid sample
        self.pa_pa = np.zeros(n_legs)
        self.pb_pa = np.zeros(n_legs)
        self.ps_pa = np.zeros(n_legs)                  # the supply at the valve's P port
        self.pressure_valid = np.zeros(n_legs, dtype=bool)
        self.pressure_fresh = np.zeros(n_legs, dtype=bool)    # a valid sample arrived since the last cycle
        # IMU_ATTITUDE (hexapod): roll, pitch, yaw of R = Rz Ry Rx
        self.attitude_rad = np.zeros(3)
        self.attitude_fresh = False                    # a valid sample arrived since the last cycle
        # IMU_RATE (hexapod): the platform's angular rate in its own (body) frame
        self.rate_rad_s = np.zeros(3)
        self.rate_fresh = False                        # a valid sample arrived since the last cycle
        # node events
        self.emergency = False                         # an EMCY with an error code from a valve node
        self.sensor_emergency = False                  # ... from a sensor's (the IMU; a stock encoder or transducer)
        self.heartbeat_age_s = np.zeros(n_nodes)       # since each node's last heartbeat
        self.stalled = False                           # the loop's clock ran past the stall limit
        self.overrun = False                           # the previous cycle missed its deadline
        self.nodes_starting = False                    # rebooted nodes being identified before their start

    def report_legs(self, position_m, force_n, valve_state: int) -> None:
        """Every leg's LEG_STATE came with these readings, exactly (no wire, no noise: what
        a linearisation feeds the controller)."""
        self.position_m[:] = position_m
        self.force_n[:] = force_n
        self.valve_state[:] = valve_state
        self.fresh.fill(True)
        self.rejected.fill(False)


class ValveCommands:
    """One cycle's outputs per leg: the CiA 408 control word (CW_D power stage enabled,
    CW_H hold, CW_M device mode active, CW_R reset on its rising edge) as 0/1 and the spool
    setpoint as a fraction of full valve input."""

    def __init__(self, n_legs: int):
        self.enable = np.ones(n_legs)       # CW_D
        self.hold = np.ones(n_legs)         # CW_H
        self.active = np.zeros(n_legs)      # CW_M
        self.reset = np.zeros(n_legs)       # CW_R
        self.spool = np.zeros(n_legs)

    def hold_all(self) -> None:
        """Every valve to HOLD: powered, spool centred."""
        self.enable.fill(1.0)
        self.hold.fill(1.0)
        self.active.fill(0.0)
        self.reset.fill(0.0)
        self.spool.fill(0.0)

    def disable_all(self) -> None:
        """Every valve DISABLED: power stage off, spool centred by its spring."""
        self.hold_all()
        self.enable.fill(0.0)
        self.hold.fill(0.0)


# -- where the interfaces' fields sit in the frames (the one map between them) ---------------------
# The DBC's signal indexes, looked up once; both sides of the bus go through these: the
# controller's loop from decoded frames into Measurements and from ValveCommands into
# VALVE_CMD; the emulated nodes (and the in-process rig) the other way.

def _indexes(message: str, *signals: str) -> tuple[int, ...]:
    index = CODECS[message].index
    return tuple(index[s] for s in signals)


LS_VALVE_STATE, LS_SENSOR_FAULT, LS_POSITION, LS_FORCE, LS_SPOOL = _indexes(
    "LEG_STATE_1", "VALVE_STATE", "SENSOR_FAULT", "POSITION", "FORCE", "SPOOL")
LP_PA, LP_PB, LP_PS, LP_FAULT_A, LP_FAULT_B = _indexes(
    "LEG_PRESSURE_1", "PA", "PB", "PS", "SENSOR_FAULT_A", "SENSOR_FAULT_B")
IMU_VALID = int(ImuStatus.VALID)
IMU_STATUS, IMU_ROLL, IMU_PITCH, IMU_YAW = _indexes("IMU_ATTITUDE", "STATUS", "ROLL", "PITCH", "YAW")
RATE_STATUS, RATE_X, RATE_Y, RATE_Z = _indexes("IMU_RATE", "STATUS", "RATE_X", "RATE_Y", "RATE_Z")
VC_D, VC_H, VC_M, VC_R, VC_SPOOL = _indexes("VALVE_CMD_1", "CW_D", "CW_H", "CW_M", "CW_R", "SPOOL_SETPOINT")


def leg_state_into(values, meas: Measurements, leg: int) -> None:
    """A decoded LEG_STATE of `leg` into the Measurements (the frame came: the caller marks it fresh)."""
    meas.position_m[leg] = values[LS_POSITION]
    meas.force_n[leg] = values[LS_FORCE]
    meas.spool[leg] = values[LS_SPOOL]
    meas.valve_state[leg] = int(values[LS_VALVE_STATE])
    meas.sensor_fault[leg] = values[LS_SENSOR_FAULT] != 0.0


def leg_state_values(values, position_m: float, force_n: float, spool: float, valve_state: int,
                     sensor_fault: bool) -> None:
    """A leg node's LEG_STATE fields."""
    values[LS_VALVE_STATE] = valve_state
    values[LS_SENSOR_FAULT] = 1 if sensor_fault else 0
    values[LS_POSITION] = position_m
    values[LS_FORCE] = force_n
    values[LS_SPOOL] = spool


def leg_pressure_into(values, pressures, leg: int) -> bool:
    """A decoded LEG_PRESSURE of `leg`: when both chamber transducers are sound, its PA, PB
    and PS into row `leg` of `pressures` (n x 3); whether they were."""
    if values[LP_FAULT_A] or values[LP_FAULT_B]:
        return False
    pressures[leg, 0] = values[LP_PA]
    pressures[leg, 1] = values[LP_PB]
    pressures[leg, 2] = values[LP_PS]
    return True


def leg_pressure_values(values, pa_pa: float, pb_pa: float, ps_pa: float) -> None:
    values[LP_PA], values[LP_PB], values[LP_PS] = pa_pa, pb_pa, ps_pa


def _imu_into(values, fields, out) -> bool:
    """A decoded IMU frame's three values into `out` when its STATUS says valid (`fields`:
    the STATUS index, then the three values')."""
    status, a, b, c = fields
    if int(values[status]) != IMU_VALID:
        return False
    out[0], out[1], out[2] = values[a], values[b], values[c]
    return True


def _imu_values(values, fields, vector) -> None:
    _, a, b, c = fields
    values[a], values[b], values[c] = vector[0], vector[1], vector[2]


ATTITUDE_FIELDS = (IMU_STATUS, IMU_ROLL, IMU_PITCH, IMU_YAW)
RATE_FIELDS = (RATE_STATUS, RATE_X, RATE_Y, RATE_Z)


def attitude_into(values, out) -> bool:
    """A decoded IMU_ATTITUDE: roll, pitch, yaw into `out` when the IMU says it is valid."""
    return _imu_into(values, ATTITUDE_FIELDS, out)


def attitude_values(values, rpy) -> None:
    _imu_values(values, ATTITUDE_FIELDS, rpy)


def rate_into(values, out) -> bool:
    """A decoded IMU_RATE: the body rates into `out` when the IMU says it is valid."""
    return _imu_into(values, RATE_FIELDS, out)


def rate_values(values, rate_rad_s) -> None:
    _imu_values(values, RATE_FIELDS, rate_rad_s)


def valve_command_values(values, cmd: ValveCommands, leg: int) -> None:
    """`leg`'s control word and setpoint into its VALVE_CMD."""
    values[VC_D] = cmd.enable[leg]
    values[VC_H] = cmd.hold[leg]
    values[VC_M] = cmd.active[leg]
    values[VC_R] = cmd.reset[leg]
    values[VC_SPOOL] = cmd.spool[leg]


def valve_command_of(values) -> tuple[bool, bool, bool, bool, float]:
    """A decoded VALVE_CMD as a valve driver takes it: (D, H, M, R, spool setpoint)."""
    return (bool(values[VC_D]), bool(values[VC_H]), bool(values[VC_M]), bool(values[VC_R]),
            float(values[VC_SPOOL]))


def payload_values(values, index, mass_kg: float, com_m, declared_kg: float) -> None:
    """CTRL_PAYLOAD from the controller's estimate (`mass_kg` NaN: not estimated, the declared
    payload is sent) and its centre of mass (NaN: not placed, COM_PLACED 0)."""
    estimating = mass_kg == mass_kg
    values[index["ESTIMATING"]] = estimating
    values[index["MASS"]] = mass_kg if estimating else declared_kg
    placed = estimating and com_m[0] == com_m[0]
    values[index["COM_PLACED"]] = placed
    for k, name in enumerate(("COM_X", "COM_Y", "COM_Z")):
        values[index[name]] = com_m[k] if placed else 0.0


def clock_values(values, index, playing: bool, scaled: bool, rate: float, motion_time_periods: float) -> None:
    """CTRL_CLOCK: the played trajectory's clock and its rate (the controller's status: 0 and 1
    while none is played)."""
    values[index["MOVING"]] = playing
    values[index["SCALED"]] = scaled
    values[index["RATE"]] = rate
    values[index["MOTION_TIME"]] = motion_time_periods


def load_values(values, index, leg: int, mass_kg: float, load_pressure_pa: float, friction_n: float) -> None:
    """CTRL_LOAD: one leg's (0-based `leg`) estimates of chapter 7.5; NaN (none yet) is sent as 0."""
    values[index["LEG"]] = leg + 1
    values[index["MASS"]] = mass_kg if mass_kg == mass_kg else 0.0
    values[index["LOAD_PRESSURE"]] = load_pressure_pa if load_pressure_pa == load_pressure_pa else 0.0
    values[index["FRICTION"]] = friction_n if friction_n == friction_n else 0.0
