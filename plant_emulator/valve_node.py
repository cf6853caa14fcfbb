"""CiA 408 valve-driver behaviour of one leg node, as pure logic (no bus, no clock).

Control word (VALVE_CMD): D (power stage enabled), H (hold), M (device mode active),
R (reset fault, on its rising edge). States INIT, DISABLED, HOLD, ACTIVE, FAULT_HOLD,
FAULT_DISABLED (the DBC's VALVE_STATE values).

- A command received during SYNC cycle k is latched and takes effect at SYNC k+1, as a
  CANopen synchronous RPDO does: `receive` latches, `on_sync` applies.
- Targets: D=0 -> DISABLED; D=1,H=1 -> HOLD; D=1,H=1,M=1 -> ACTIVE. ACTIVE is entered only
  from HOLD (a disabled valve first holds for one cycle).
- Command timeout: while HOLD or ACTIVE, `command_timeout_syncs` SYNCs in a row without a
  valid VALVE_CMD -> FAULT_HOLD (COMMAND_TIMEOUT, or E2E_ERROR when invalid frames did
  arrive). Lost SYNC (wall clock, checked by the node layer) -> FAULT_HOLD (SYNC_TIMEOUT).
  A spool that does not follow its setpoint -> FAULT_HOLD (SPOOL_JAM).
- In FAULT_HOLD the spool is held centred (closed centre: the cylinder is locked); D=0
  there -> FAULT_DISABLED. Only a rising edge of R leaves a fault: to HOLD if D=1, else to
  DISABLED.
- In every state but ACTIVE the spool setpoint is the hold setpoint 0: a valve whose power
  stage is off returns to null mechanically (the E050's feedback spring).
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.enums import VALVE_FAULT_STATES as FAULT_STATES
from protocol.enums import EmcyCode, ValveState
from protocol.enums import ValveFaultReason as FaultReason

# CiA 301 error register bits: 0 generic error, 4 communication error
GENERIC, COMMUNICATION = 0x01, 0x10
EMCY_CODES = {
    FaultReason.COMMAND_TIMEOUT: (EmcyCode.RPDO_TIMEOUT, GENERIC | COMMUNICATION),
    FaultReason.SYNC_TIMEOUT: (EmcyCode.COMMUNICATION, GENERIC | COMMUNICATION),     # SYNC lost
    FaultReason.E2E_ERROR: (EmcyCode.PROTOCOL, GENERIC | COMMUNICATION),
    FaultReason.SPOOL_JAM: (EmcyCode.CONTROL_DEVIATION, GENERIC),
    FaultReason.SUPPLY_LOW: (EmcyCode.SUPPLY_LOW, GENERIC),
    FaultReason.INTERNAL: (EmcyCode.SOFTWARE, GENERIC),
}
POWERED_STATES = (ValveState.HOLD, ValveState.ACTIVE)


@dataclass
class Emergency:
    """An EMCY to send: error code 0 is the CiA 301 'error reset'."""
    error_code: int
    error_register: int
    state: ValveState
    reason: FaultReason
    info: int


class ValveDriver:
    def __init__(self, command_timeout_syncs: int = 3, jam_threshold: float = 0.1, jam_syncs: int = 10):
        self.command_timeout_syncs = command_timeout_syncs
        self.jam_threshold = jam_threshold
        self.jam_syncs = jam_syncs
        self.state = ValveState.INIT
        self.fault_reason = FaultReason.NONE
        self.setpoint = 0.0             # applied spool setpoint, fraction of full input
        self.missed_syncs = 0
        self.invalid_since_valid = 0
        self.faults = 0
        self._latched: tuple[bool, bool, bool, bool, float] | None = None
        self._reset_bit = False
        self._jam_count = 0

    def boot(self) -> None:
        self.state = ValveState.DISABLED

    # -- input ------------------------------------------------------------------------------
    def receive(self, d: bool, h: bool, m: bool, r: bool, setpoint: float) -> None:
        """A valid (E2E OK) VALVE_CMD; applied at the next SYNC."""
        self._latched = (d, h, m, r, min(max(setpoint, -1.0), 1.0))

    def receive_invalid(self) -> None:
        """A VALVE_CMD rejected by the E2E check (counted; does not refresh the timeout)."""
        self.invalid_since_valid += 1

    # -- SYNC -------------------------------------------------------------------------------
    def on_sync(self) -> Emergency | None:
        latched, self._latched = self._latched, None
        if latched is None:
            self.missed_syncs += 1
            if self.state in POWERED_STATES and self.missed_syncs >= self.command_timeout_syncs:
                reason = FaultReason.E2E_ERROR if self.invalid_since_valid else FaultReason.COMMAND_TIMEOUT
                return self._fault(reason, self.missed_syncs)
            return None
        self.missed_syncs = 0
        self.invalid_since_valid = 0
        d, h, m, r, setpoint = latched
        rising_reset = r and not self._reset_bit
        self._reset_bit = r
        if self.state in FAULT_STATES:
            if rising_reset:
                self.state = ValveState.HOLD if d else ValveState.DISABLED
                self.fault_reason = FaultReason.NONE
                self._jam_count = 0
                self.setpoint = 0.0
                return Emergency(EmcyCode.NO_ERROR, 0x00, self.state, FaultReason.NONE, 0)
            if self.state is ValveState.FAULT_HOLD and not d:
                self.state = ValveState.FAULT_DISABLED
            self.setpoint = 0.0
            return None
        if self.state is ValveState.INIT:
            return None
        if not d or not h:
            self.state = ValveState.DISABLED
        elif m and self.state is ValveState.HOLD or m and self.state is ValveState.ACTIVE:
            self.state = ValveState.ACTIVE
        else:
            self.state = ValveState.HOLD
        self.setpoint = setpoint if self.state is ValveState.ACTIVE else 0.0
        return None

    def sync_lost(self, periods: float) -> Emergency | None:
        """The node layer saw no SYNC for too long."""
        if self.state in POWERED_STATES:
            return self._fault(FaultReason.SYNC_TIMEOUT, int(periods))
        return None

    def check_spool(self, actual: float, demand: float) -> Emergency | None:
        """Control-deviation monitor, once per SYNC while powered: the actual spool against
        the demand it followed over the last period (a setpoint received since is not yet
        the spool's: against it any ramp faster than the threshold per period would trip)."""
        if self.state not in POWERED_STATES:
            self._jam_count = 0
            return None
        if abs(demand - actual) > self.jam_threshold:
            self._jam_count += 1
            if self._jam_count >= self.jam_syncs:
                return self._fault(FaultReason.SPOOL_JAM, self._jam_count)
        else:
            self._jam_count = 0
        return None

    def _fault(self, reason: FaultReason, info: int) -> Emergency:
        self.state = ValveState.FAULT_HOLD
        self.fault_reason = reason
        self.setpoint = 0.0
        self.faults += 1
        code, register = EMCY_CODES[reason]
        return Emergency(code, register, self.state, reason, min(info, 0xFFFF))

    @property
    def spool_command(self) -> float:
        return self.setpoint if self.state is ValveState.ACTIVE else 0.0
