"""The controller's state machine: its states, the one place its faults are latched, and
the host's commands.

States (CTRL_STATUS.STATE): BOOT -> IDLE (valves HOLD) -> READY (valves ACTIVE, holding
position) -> HOMING / RUNNING / STOPPING -> READY; FAULT (valves HOLD) and ESTOP (valves
DISABLED) from anywhere; only RESET leaves them, to IDLE. The first fault latches its code.

HOST_CMD transitions (anything else is acknowledged BAD_STATE and changes nothing):
  ENABLE   IDLE -> READY (READY: no change)    DISABLE  IDLE, READY -> IDLE
  HOME     IDLE, READY -> HOMING -> READY       PARK     IDLE, READY -> HOMING -> IDLE
  START    READY (waypoints queued) -> RUNNING STOP     RUNNING, HOMING -> STOPPING -> READY
  ESTOP    any -> ESTOP (same cycle)           RESET    FAULT, ESTOP -> IDLE
  SELECT_CONTROLLER (a CTRL_STATUS.CONTROLLER value) in IDLE or READY
  CLEAR_WAYPOINTS outside RUNNING; NOP always.
The supervisor decides; the controller carries out the resulting `action` in the same cycle.
"""

from __future__ import annotations

from enum import IntEnum

from protocol.enums import Ack, Command, ControllerKind, EmcyCode, Fault, State


class Action(IntEnum):
    """What the controller must do this cycle after an accepted command."""
    NONE = 0
    ENABLE = 1
    HOME = 2
    PARK = 3
    START = 4
    STOP = 5
    RESET = 6
    CLEAR = 7


MOVING = (State.HOMING, State.RUNNING, State.STOPPING)
ACTIVE = (State.READY,) + MOVING          # valves ACTIVE, the joint controller runs
LATCHED = (State.FAULT, State.ESTOP)
# the CiA 301 error class of the controller's EMCY for each latched fault (GENERIC otherwise)
EMCY_OF_FAULT = {Fault.SENSOR_TIMEOUT: EmcyCode.RPDO_TIMEOUT, Fault.E2E_ERROR: EmcyCode.PROTOCOL,
                 Fault.HEARTBEAT_LOST: EmcyCode.COMMUNICATION, Fault.OVERRUN: EmcyCode.SOFTWARE,
                 Fault.NOT_FINITE: EmcyCode.SOFTWARE, Fault.DK_FAILURE: EmcyCode.SOFTWARE,
                 Fault.SUPPLY_PRESSURE: EmcyCode.SUPPLY_LOW, Fault.TRACKING_ERROR: EmcyCode.CONTROL_DEVIATION,
                 Fault.POSITION_LIMIT: EmcyCode.CONTROL_DEVIATION, Fault.FORCE_LIMIT: EmcyCode.CONTROL_DEVIATION,
                 Fault.VELOCITY_LIMIT: EmcyCode.CONTROL_DEVIATION,
                 Fault.MOTION_PLAUSIBILITY: EmcyCode.CONTROL_DEVIATION,
                 Fault.ATTITUDE_MISMATCH: EmcyCode.CONTROL_DEVIATION,
                 Fault.ACTUATOR_RESIDUAL: EmcyCode.CONTROL_DEVIATION, Fault.LOAD_CELL: EmcyCode.GENERIC,
                 Fault.SPOOL_MISMATCH: EmcyCode.CONTROL_DEVIATION, Fault.CHAMBER_PRESSURE: EmcyCode.CONTROL_DEVIATION}


def emergency_code(fault: Fault) -> EmcyCode:
    return EMCY_OF_FAULT.get(fault, EmcyCode.GENERIC)
CONTROLLER_VALUES = frozenset(int(kind) for kind in ControllerKind)


class Supervisor:
    def __init__(self, controller: int = ControllerKind.PI):
        self.state = State.BOOT
        self.fault_code = Fault.NONE
        self.fault_leg = 0                 # the leg (1..n) the latched fault was isolated to, 0: none
        self.controller = int(controller)
        self.action = Action.NONE
        self.parking = False
        self.faults = 0                    # faults latched since start
        self.transitions = 0

    def _go(self, state: State) -> None:
        if state != self.state:
            self.state = state
            self.transitions += 1

    @property
    def active(self) -> bool:
        return self.state in ACTIVE

    def booted(self, auto_enable: bool) -> None:
        """Activation finished (valves in HOLD): IDLE, or READY straight away."""
        if self.state is State.BOOT:
            self._go(State.IDLE)
            if auto_enable:
                self.command(Command.ENABLE, 0)

    def fault(self, code: Fault, leg: int = 0) -> None:
        """Latch a fault: FAULT (valves HOLD) unless already in FAULT or ESTOP; NONE is no fault.
        `leg` (1..n): the leg it was isolated to."""
        if self.state in LATCHED or code is Fault.NONE:
            return
        self.fault_code = code
        self.fault_leg = leg
        self.faults += 1
        self.parking = False
        self._go(State.FAULT)

    def command(self, command: int, argument: int) -> Ack:
        try:
            command = Command(command)
        except ValueError:
            return Ack.UNKNOWN_COMMAND
        s = self.state
        if command is Command.NOP:
            return Ack.ACCEPTED
        if command is Command.ESTOP:
            if s is not State.ESTOP:
                self.fault_code = Fault.ESTOP
                self.fault_leg = 0
                self.parking = False
                self._go(State.ESTOP)
            return Ack.ACCEPTED
        if command is Command.RESET:
            if s not in LATCHED:
                return Ack.BAD_STATE
            self.fault_code = Fault.NONE
            self.fault_leg = 0
            self.action = Action.RESET
            self._go(State.IDLE)
            return Ack.ACCEPTED
        if command is Command.SELECT_CONTROLLER:
            if argument not in CONTROLLER_VALUES:
                return Ack.BAD_ARGUMENT
            if s not in (State.IDLE, State.READY):
                return Ack.BAD_STATE
            self.controller = int(argument)
            return Ack.ACCEPTED
        if command is Command.ENABLE:
            if s is State.READY:             # a harmless repeat: already enabled, nothing changes
                return Ack.ACCEPTED
            if s is not State.IDLE:
                return Ack.BAD_STATE
            self.action = Action.ENABLE
            self._go(State.READY)
            return Ack.ACCEPTED
        if command is Command.DISABLE:
            if s not in (State.IDLE, State.READY):
                return Ack.BAD_STATE
            self._go(State.IDLE)
            return Ack.ACCEPTED
        if command in (Command.HOME, Command.PARK):
            if s not in (State.IDLE, State.READY):
                return Ack.BAD_STATE
            self.parking = command is Command.PARK
            self.action = Action.PARK if self.parking else Action.HOME
            self._go(State.HOMING)
            return Ack.ACCEPTED
        if command is Command.START:
            if s is not State.READY:
                return Ack.BAD_STATE
            self.action = Action.START
            return Ack.ACCEPTED          # the controller moves to RUNNING when the queue is not empty
        if command is Command.STOP:
            if s not in (State.RUNNING, State.HOMING):
                return Ack.BAD_STATE
            self.parking = False
            self.action = Action.STOP
            self._go(State.STOPPING)
            return Ack.ACCEPTED
        if command is Command.CLEAR_WAYPOINTS:
            if s is State.RUNNING:
                return Ack.BAD_STATE
            self.action = Action.CLEAR
            return Ack.ACCEPTED
        return Ack.UNKNOWN_COMMAND

    def start_running(self) -> None:
        self._go(State.RUNNING)

    def shut_down(self) -> None:
        """The daemon stops: the valves are forced to HOLD from any state, so IDLE (the active
        checks end with them); a latched fault or e-stop stays."""
        if self.state not in LATCHED:
            self.parking = False
            self._go(State.IDLE)

    def motion_done(self) -> None:
        """The current move reached its end at rest."""
        if self.state in MOVING:
            parked = self.state is State.HOMING and self.parking
            self.parking = False
            self._go(State.IDLE if parked else State.READY)
