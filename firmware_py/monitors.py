"""The checks of every cycle. Each returns the fault it sees (`Fault.NONE` when there is
none) and latches nothing: the controller hands the result to the supervisor, the one
place faults are latched, in the cycle they are seen. In place on arrays made here.

- LoopMonitor: the loop itself (a stall, overruns in a row);
- NodeMonitor: the nodes (heartbeats, EMCY, the valves' reported states);
- FrameMonitor: LEG_STATE frames missing or E2E-rejected in a row, a sensor's fault bit;
- LimitMonitor: non-finite numbers, load-cell force, end-stop guard (with the recovery of a
  leg enabled inside it), velocity, tracking error.
Plausibility of the measurements (motion against command, encoders against the IMU) is in
plausibility.py.
"""

from __future__ import annotations

import numpy as np

from protocol.enums import VALVE_FAULT_STATES, Fault

from .config import ControllerConfig

RECOVERY_INSET_M = 2e-3                # enabled inside the end-stop guard: held this far inside it
RECOVERY_CYCLES = 500                  # ... and back inside the guard within 1 s (500 Hz)
RECOVERY_SLACK_M = 0.5e-3              # ... never more than this further out (encoder steps, noise)


class LoopMonitor:
    def __init__(self, cfg: ControllerConfig):
        self.cfg = cfg
        self.overruns_in_row = 0

    def reset(self) -> None:
        self.overruns_in_row = 0

    def check(self, stalled: bool, overrun: bool) -> Fault:
        """A stall: the valves' SYNC watchdog has tripped meanwhile, nothing received late may
        be acted on as if nothing happened. Overruns: too many in a row."""
        self.overruns_in_row = self.overruns_in_row + 1 if overrun else 0
        if stalled or self.overruns_in_row >= self.cfg.overruns_fault:
            return Fault.OVERRUN
        return Fault.NONE


class NodeMonitor:
    def __init__(self, cfg: ControllerConfig, n_legs: int):
        self.cfg = cfg
        self._valve_fault = np.zeros(n_legs, dtype=bool)
        self._scratch = np.zeros(n_legs, dtype=bool)

    def check_heartbeats(self, heartbeat_age_s: np.ndarray) -> Fault:
        """A node whose heartbeat is overdue."""
        return Fault.HEARTBEAT_LOST if heartbeat_age_s.max() > self.cfg.heartbeat_timeout_s else Fault.NONE

    @staticmethod
    def check_emergency(emergency: bool, in_reset: bool) -> Fault:
        """An EMCY with an error code, except while the valves' faults are being reset (they
        announce the reset with EMCYs of their own)."""
        return Fault.VALVE_FAULT if emergency and not in_reset else Fault.NONE

    def check_valves(self, valve_state: np.ndarray) -> Fault:
        """A valve that reports a fault state in its LEG_STATE."""
        self._valve_fault[:] = False
        for state in VALVE_FAULT_STATES:
            np.equal(valve_state, state, out=self._scratch)
            np.logical_or(self._valve_fault, self._scratch, out=self._valve_fault)
        return Fault.VALVE_FAULT if self._valve_fault.any() else Fault.NONE


class FrameMonitor:
    def __init__(self, cfg: ControllerConfig, n_legs: int):
        self.cfg = cfg
        self.missing = np.zeros(n_legs, dtype=np.int64)     # cycles in a row without a valid frame
        self.rejected = np.zeros(n_legs, dtype=np.int64)    # ... of which a frame came and was rejected
        self._mask = np.zeros(n_legs, dtype=bool)

    def reset(self) -> None:
        self.missing[:] = 0
        self.rejected[:] = 0

    def check(self, fresh: np.ndarray, rejected: np.ndarray, sensor_fault: np.ndarray) -> Fault:
        np.logical_not(fresh, out=self._mask)
        np.multiply(self.missing, self._mask, out=self.missing)
        np.add(self.missing, self._mask, out=self.missing)
        np.logical_and(rejected, self._mask, out=self._mask)
        np.multiply(self.rejected, self._mask, out=self.rejected)
        np.add(self.rejected, self._mask, out=self.rejected)
        if self.rejected.max() >= self.cfg.e2e_errors_fault:
            return Fault.E2E_ERROR
        if self.missing.max() >= self.cfg.missing_frames_fault:
            return Fault.SENSOR_TIMEOUT
        if sensor_fault.any():
            return Fault.SENSOR_FAULT
        return Fault.NONE


class LimitMonitor:
    def __init__(self, cfg: ControllerConfig, n_legs: int, stroke_m: float):
        self.cfg, self.stroke_m = cfg, stroke_m
        # enabled with a leg inside the end-stop guard (after a POSITION_LIMIT fault): it is
        # held just inside the guard and may come back, but never go further out
        self.recovering = np.zeros(n_legs, dtype=bool)
        self.recovery_from = np.zeros(n_legs)
        self.recovery_cycles = 0
        self._mask = np.zeros(n_legs, dtype=bool)
        self._abs = np.zeros(n_legs)

    def enable_target(self, position_m: np.ndarray) -> np.ndarray:
        """Where to hold legs that are enabled: where they are, or RECOVERY_INSET_M inside the
        end-stop guard for those outside it (marked recovering)."""
        low = self.cfg.stroke_margin_m + RECOVERY_INSET_M
        high = self.stroke_m - low
        target = np.clip(position_m, low, high)
        np.not_equal(target, position_m, out=self.recovering)
        self.recovery_from[:] = position_m
        self.recovery_cycles = RECOVERY_CYCLES if self.recovering.any() else 0
        return target

    def check_always(self, u_v: np.ndarray, kalman_x: np.ndarray, force_n: np.ndarray,
                     finite_scratch: np.ndarray) -> Fault:
        """Whatever the state: non-finite control or estimates, the load cell's range."""
        np.isfinite(u_v, out=self._mask)
        finite = self._mask.all()
        np.isfinite(kalman_x, out=finite_scratch)
        if not (finite and finite_scratch.all()):
            return Fault.NOT_FINITE
        np.abs(force_n, out=self._abs)
        if self._abs.max() > self.cfg.force_max_n:
            return Fault.FORCE_LIMIT
        return Fault.NONE

    def check_active(self, position_m: np.ndarray, velocity_m_s: np.ndarray, error_m: np.ndarray) -> Fault:
        """While the valves are ACTIVE: end-stop guard, velocity, tracking error."""
        cfg = self.cfg
        margin = cfg.stroke_margin_m
        if self.recovery_cycles > 0:
            self.recovery_cycles -= 1
        if position_m.min() < margin or position_m.max() > self.stroke_m - margin:
            if self._position_fault(position_m, margin):
                return Fault.POSITION_LIMIT
        elif self.recovery_cycles > 0:
            self.recovering[:] = False
            self.recovery_cycles = 0
        np.abs(velocity_m_s, out=self._abs)
        if self._abs.max() > cfg.velocity_max_m_s:
            return Fault.VELOCITY_LIMIT
        np.abs(error_m, out=self._abs)
        if self._abs.max() > cfg.tracking_error_max_m:
            return Fault.TRACKING_ERROR
        return Fault.NONE

    def _position_fault(self, position_m: np.ndarray, margin: float) -> bool:
        """A leg inside the guard is a fault, unless it is coming back from where it was
        enabled (within RECOVERY_CYCLES and never further out)."""
        for leg in range(position_m.shape[0]):
            y = position_m[leg]
            if margin <= y <= self.stroke_m - margin:
                self.recovering[leg] = False
                continue
            edge = margin if y < margin else self.stroke_m - margin
            coming_back = (self.recovering[leg] and self.recovery_cycles > 0
                           and abs(y - edge) <= abs(self.recovery_from[leg] - edge) + RECOVERY_SLACK_M)
            if not coming_back:
                return True
        return False
