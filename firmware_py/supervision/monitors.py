"""The checks of every cycle. Each returns the fault it sees (`Fault.NONE` when there is
none) and latches nothing: the controller hands the result to the supervisor, the one
place faults are latched, in the cycle they are seen. The per-leg work is in numba kernels
on arrays made here (a NumPy call on a six-element array costs about a microsecond).

- LoopMonitor: the loop itself (a stall, overruns in a row);
- NodeMonitor: the nodes (heartbeats, EMCY, the valves' reported states);
- FrameMonitor: LEG_STATE frames missing or E2E-rejected in a row, a sensor's fault bit;
- LimitMonitor: non-finite numbers, load-cell force, end-stop guard (with the recovery of a
  leg enabled inside it), velocity, tracking error.
Plausibility of the measurements (motion against command, encoders against the IMU) is in
plausibility.py.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.config import Limits, Supervisor
from protocol.enums import VALVE_FAULT_STATES, Fault

RECOVERY_INSET_M = 2e-3                # enabled inside the end-stop guard: held this far inside it
RECOVERY_CYCLES = 500                  # ... and back inside the guard within 1 s (500 Hz)
RECOVERY_SLACK_M = 0.5e-3              # ... never more than this further out (encoder steps, noise)
# fault codes as the kernels return them (0: none)
NONE, E2E_ERROR, SENSOR_TIMEOUT, SENSOR_FAULT = (int(Fault.NONE), int(Fault.E2E_ERROR), int(Fault.SENSOR_TIMEOUT),
                                                 int(Fault.SENSOR_FAULT))
NOT_FINITE, FORCE_LIMIT, POSITION_LIMIT = int(Fault.NOT_FINITE), int(Fault.FORCE_LIMIT), int(Fault.POSITION_LIMIT)
VELOCITY_LIMIT, TRACKING_ERROR = int(Fault.VELOCITY_LIMIT), int(Fault.TRACKING_ERROR)


class LoopMonitor:
    def __init__(self, supervisor: Supervisor):
        self.overruns_fault = supervisor.overruns_fault
        self.overruns_in_row = 0

    def reset(self) -> None:
        self.overruns_in_row = 0

    def check(self, stalled: bool, overrun: bool) -> Fault:
        """A stall: the valves' SYNC watchdog has tripped meanwhile, nothing received late may
        be acted on as if nothing happened. Overruns: too many in a row."""
        self.overruns_in_row = self.overruns_in_row + 1 if overrun else 0
        if stalled or self.overruns_in_row >= self.overruns_fault:
            return Fault.OVERRUN
        return Fault.NONE


@njit(cache=True)
def any_above(values, limit):
    """Whether any entry exceeds `limit`."""
    for i in range(values.shape[0]):
        if values[i] > limit:
            return True
    return False


@njit(cache=True)
def any_beyond(values, limit):
    """Whether any entry's magnitude exceeds `limit`."""
    for i in range(values.shape[0]):
        if abs(values[i]) > limit:
            return True
    return False


@njit(cache=True)
def all_set(flags):
    """Whether every entry is true (no reduction's result buffer, as `ndarray.all` makes)."""
    for i in range(flags.shape[0]):
        if not flags[i]:
            return False
    return True


@njit(cache=True)
def any_in(values, a, b):
    """Whether any entry equals a or b."""
    for i in range(values.shape[0]):
        if values[i] == a or values[i] == b:
            return True
    return False


class NodeMonitor:
    def __init__(self, heartbeat_timeout_s: float):
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self._fault_states = tuple(int(s) for s in VALVE_FAULT_STATES)

    def check_heartbeats(self, heartbeat_age_s: np.ndarray) -> Fault:
        """A node whose heartbeat is overdue."""
        return Fault.HEARTBEAT_LOST if any_above(heartbeat_age_s, self.heartbeat_timeout_s) else Fault.NONE

    @staticmethod
    def check_emergency(valve: bool, sensor: bool, in_reset: bool) -> Fault:
        """An EMCY with an error code, named by its source (a valve: VALVE_FAULT, a sensor's
        node, the IMU or a stock encoder or transducer: SENSOR_FAULT), except while the nodes'
        faults are being reset (they announce the reset with EMCYs of their own)."""
        if in_reset:
            return Fault.NONE
        return Fault.VALVE_FAULT if valve else Fault.SENSOR_FAULT if sensor else Fault.NONE

    def check_valves(self, valve_state: np.ndarray) -> Fault:
        """A valve that reports a fault state in its LEG_STATE."""
        return Fault.VALVE_FAULT if any_in(valve_state, *self._fault_states) else Fault.NONE


@njit(cache=True)
def frames_check(fresh, rejected, sensor_fault, missing, rejected_run, e2e_limit, missing_limit):
    """Count, per leg, cycles in a row without a valid frame and those of them with a frame
    that was rejected; the fault code of the first limit reached (E2E first)."""
    worst_rejected, worst_missing, sensor = 0, 0, False
    for leg in range(fresh.shape[0]):
        if fresh[leg]:
            missing[leg] = 0
            rejected_run[leg] = 0
        else:
            missing[leg] += 1
            rejected_run[leg] = rejected_run[leg] + 1 if rejected[leg] else 0
        worst_rejected = max(worst_rejected, rejected_run[leg])
        worst_missing = max(worst_missing, missing[leg])
        sensor = sensor or sensor_fault[leg]
    if worst_rejected >= e2e_limit:
        return E2E_ERROR
    if worst_missing >= missing_limit:
        return SENSOR_TIMEOUT
    return SENSOR_FAULT if sensor else NONE


class FrameMonitor:
    def __init__(self, supervisor: Supervisor, n_legs: int):
        self.e2e_limit, self.missing_limit = supervisor.e2e_errors_fault, supervisor.missing_frames_fault
        self.missing = np.zeros(n_legs, dtype=np.int64)     # cycles in a row without a valid frame
        self.rejected = np.zeros(n_legs, dtype=np.int64)    # ... of which a frame came and was rejected

    def reset(self) -> None:
        self.missing.fill(0)
        self.rejected.fill(0)

    def check(self, fresh: np.ndarray, rejected: np.ndarray, sensor_fault: np.ndarray) -> Fault:
        code = frames_check(fresh, rejected, sensor_fault, self.missing, self.rejected, self.e2e_limit,
                            self.missing_limit)
        return Fault(code) if code else Fault.NONE

    def leg_of(self, code: Fault, sensor_fault: np.ndarray) -> int:
        """The leg (0-based) a fault of `check` came from (an event: it may allocate)."""
        runs = {Fault.E2E_ERROR: self.rejected, Fault.SENSOR_TIMEOUT: self.missing}.get(code, sensor_fault)
        return int(np.argmax(runs))


@njit(cache=True)
def always_check(u_v, kalman_x, force_n, force_max_n):
    """Non-finite control or estimates, then the load cell's range."""
    for leg in range(u_v.shape[0]):
        if not math.isfinite(u_v[leg]):
            return NOT_FINITE
        for k in range(kalman_x.shape[1]):
            if not math.isfinite(kalman_x[leg, k]):
                return NOT_FINITE
    for leg in range(force_n.shape[0]):
        if abs(force_n[leg]) > force_max_n:
            return FORCE_LIMIT
    return NONE


@njit(cache=True)
def active_check(position, velocity, error, margin, stroke, velocity_max, tracking_max, recovering, recovery_from,
                 recovery_left):
    """End-stop guard (a leg enabled inside it may come back for recovery_left[0] cycles, never
    further out), velocity, tracking error; recovery_left counts down here."""
    if recovery_left[0] > 0:
        recovery_left[0] -= 1
    inside = True
    for leg in range(position.shape[0]):
        if position[leg] < margin or position[leg] > stroke - margin:
            inside = False
    if inside:
        if recovery_left[0] > 0:
            for leg in range(recovering.shape[0]):
                recovering[leg] = False
            recovery_left[0] = 0
    else:
        for leg in range(position.shape[0]):
            y = position[leg]
            if margin <= y <= stroke - margin:
                recovering[leg] = False
                continue
            edge = margin if y < margin else stroke - margin
            coming_back = (recovering[leg] and recovery_left[0] > 0
                           and abs(y - edge) <= abs(recovery_from[leg] - edge) + RECOVERY_SLACK_M)
            if not coming_back:
                return POSITION_LIMIT
    for leg in range(velocity.shape[0]):
        if abs(velocity[leg]) > velocity_max:
            return VELOCITY_LIMIT
    for leg in range(error.shape[0]):
        if abs(error[leg]) > tracking_max:
            return TRACKING_ERROR
    return NONE


@njit(cache=True)
def pose_beyond(pose_error, position_max, angle_max) -> bool:
    """The platform's position error (first three) or rotation (last three) beyond its bound."""
    position = math.sqrt(pose_error[0] ** 2 + pose_error[1] ** 2 + pose_error[2] ** 2)
    angle = math.sqrt(pose_error[3] ** 2 + pose_error[4] ** 2 + pose_error[5] ** 2)
    return position > position_max or angle > angle_max


class LimitMonitor:
    def __init__(self, limits: Limits, n_legs: int, stroke_m: float):
        self.limits, self.stroke_m = limits, stroke_m
        # enabled with a leg inside the end-stop guard (after a POSITION_LIMIT fault): it is
        # held just inside the guard and may come back, but never go further out
        self.recovering = np.zeros(n_legs, dtype=bool)
        self.recovery_from = np.zeros(n_legs)
        self.recovery_left = np.zeros(1, dtype=np.int64)    # cycles it may still take

    def enable_target(self, position_m: np.ndarray) -> np.ndarray:
        """Where to hold legs that are enabled: where they are, or RECOVERY_INSET_M inside the
        end-stop guard for those outside it (marked recovering)."""
        low = self.limits.stroke_margin_m + RECOVERY_INSET_M
        high = self.stroke_m - low
        target = np.clip(position_m, low, high)
        np.not_equal(target, position_m, out=self.recovering)
        self.recovery_from[:] = position_m
        self.recovery_left[0] = RECOVERY_CYCLES if self.recovering.any() else 0
        return target

    def check_always(self, u_v: np.ndarray, kalman_x: np.ndarray, force_n: np.ndarray) -> Fault:
        """Whatever the state: non-finite control or estimates, the load cell's range."""
        code = always_check(u_v, kalman_x, force_n, self.limits.force_max_n)
        return Fault(code) if code else Fault.NONE

    def check_active(self, position_m: np.ndarray, velocity_m_s: np.ndarray, error_m: np.ndarray) -> Fault:
        """While the valves are ACTIVE: end-stop guard, velocity, tracking error."""
        limits = self.limits
        code = active_check(position_m, velocity_m_s, error_m, limits.stroke_margin_m, self.stroke_m,
                            limits.velocity_max_m_s, limits.tracking_error_max_m, self.recovering, self.recovery_from,
                            self.recovery_left)
        return Fault(code) if code else Fault.NONE
