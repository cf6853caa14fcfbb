"""Supervisor: the controller's state machine, its faults and the host's commands.

States (CTRL_STATUS.STATE): BOOT -> IDLE (valves HOLD) -> READY (valves ACTIVE, holding
position) -> HOMING / RUNNING / STOPPING -> READY; FAULT (valves HOLD) and ESTOP (valves
DISABLED) from anywhere; only RESET leaves them, to IDLE. The first fault latches its code.

HOST_CMD transitions (anything else is acknowledged BAD_STATE and changes nothing):
  ENABLE   IDLE -> READY                       DISABLE  READY -> IDLE
  HOME     IDLE, READY -> HOMING -> READY       PARK     IDLE, READY -> HOMING -> IDLE
  START    READY (waypoints queued) -> RUNNING STOP     RUNNING, HOMING -> STOPPING -> READY
  ESTOP    any -> ESTOP (same cycle)           RESET    FAULT, ESTOP -> IDLE
  SELECT_CONTROLLER (0 PI, 1 ADAPTIVE, 2 MODEL_BASED) in IDLE or READY
  CLEAR_WAYPOINTS outside RUNNING; NOP always.
The supervisor decides; the core carries out the resulting `action` in the same cycle.
"""

from __future__ import annotations

from enum import IntEnum


class State(IntEnum):
    BOOT = 0
    IDLE = 1
    HOMING = 2
    READY = 3
    RUNNING = 4
    STOPPING = 5
    FAULT = 6
    ESTOP = 7


class Fault(IntEnum):          # CTRL_STATUS.FAULT_CODE (DBC value table)
    NONE = 0
    SENSOR_TIMEOUT = 1
    E2E_ERROR = 2
    VALVE_FAULT = 3
    POSITION_LIMIT = 4
    FORCE_LIMIT = 5
    DK_FAILURE = 6
    SINGULARITY = 7
    NOT_FINITE = 8
    OVERRUN = 9
    TRACKING_ERROR = 10
    SUPPLY_PRESSURE = 11
    ESTOP = 12
    HEARTBEAT_LOST = 13
    SENSOR_FAULT = 14
    VELOCITY_LIMIT = 15
    MOTION_PLAUSIBILITY = 16   # a valve driven hard that does not move its cylinder (plausibility.py)
    ATTITUDE_MISMATCH = 17     # the encoders' platform attitude disagrees with the IMU's (plausibility.py)


class Command(IntEnum):        # HOST_CMD.COMMAND
    NOP = 0
    ENABLE = 1
    DISABLE = 2
    HOME = 3
    PARK = 4
    ESTOP = 5
    RESET = 6
    SELECT_CONTROLLER = 7
    START = 8
    STOP = 9
    CLEAR_WAYPOINTS = 10


class Ack(IntEnum):            # CTRL_ACK.RESULT
    ACCEPTED = 0
    BAD_STATE = 1
    OUTSIDE_WORKSPACE = 2
    SINGULAR = 3
    TOO_FAST = 4
    NOT_FINITE = 5
    SEQUENCE_GAP = 6
    QUEUE_FULL = 7
    INCOMPLETE = 8
    UNKNOWN_COMMAND = 9
    BAD_ARGUMENT = 10


class Action(IntEnum):         # what the core must do this cycle
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
N_CONTROLLERS = 3


class Supervisor:
    def __init__(self, controller: int = 0):
        self.state = State.BOOT
        self.fault_code = Fault.NONE
        self.controller = controller
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

    def fault(self, code: Fault) -> None:
        """Latch a fault: FAULT (valves HOLD) unless already in FAULT or ESTOP."""
        if self.state in (State.FAULT, State.ESTOP) or code is Fault.NONE:
            return
        self.fault_code = code
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
                self.parking = False
                self._go(State.ESTOP)
            return Ack.ACCEPTED
        if command is Command.RESET:
            if s not in (State.FAULT, State.ESTOP):
                return Ack.BAD_STATE
            self.fault_code = Fault.NONE
            self.action = Action.RESET
            self._go(State.IDLE)
            return Ack.ACCEPTED
        if command is Command.SELECT_CONTROLLER:
            if not 0 <= argument < N_CONTROLLERS:
                return Ack.BAD_ARGUMENT
            if s not in (State.IDLE, State.READY):
                return Ack.BAD_STATE
            self.controller = int(argument)
            return Ack.ACCEPTED
        if command is Command.ENABLE:
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
            return Ack.ACCEPTED          # the core moves to RUNNING when the queue is not empty
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

    def motion_done(self) -> None:
        """The current move reached its end at rest."""
        if self.state in MOVING:
            parked = self.state is State.HOMING and self.parking
            self.parking = False
            self._go(State.IDLE if parked else State.READY)
