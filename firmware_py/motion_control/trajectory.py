"""Sinusoidal-linear-sinusoidal (SLS) joint trajectories (thesis chapter 11.3).

A point-to-point segment of duration tm has three regimes (eq. 11.1-11.3): a sinusoidal
acceleration of length ta, constant velocity, and a sinusoidal deceleration of length
td = ta to rest, with w = pi / ta. Acceleration is zero at every regime boundary, so
velocity and acceleration are continuous. Coefficients (eq. 11.4, written out; D = yf - y0,
v0 the initial velocity):
    b1 = (D - v0 ta / 2) / (tm - ta)          constant velocity
    a1 = (v0 + b1) / 2,  a2 = (b1 - v0) / (2 w)
    y = y0 + a1 t - a2 sin(w t)               0 <= t < ta
    y = y0 + a1 ta + b1 (t - ta)              ta <= t < tm - ta
    y = c0 + c1 t' + c2 sin(w t'),  c1 = b1 / 2,  c2 = c1 / w,  t' = t - (tm - ta)
Through several points the deceleration is dropped except on the last segment (chapter
11.3): an intermediate segment accelerates from the incoming velocity v0 to
b1 = (D - v0 ta / 2) / (tm - ta / 2) and reaches the next point at that velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

# coefficient columns of one segment, per joint
Y0, A1, A2, B1, T_START, TA, TM, DECEL = range(8)


def sls_coefficients(y0, v0, yf, ta_s: float, tm_s: float, decelerate: bool) -> np.ndarray:
    """(n_joints, 8) coefficients of one segment; see the module docstring."""
    if not (ta_s > 0.0 and tm_s >= (2.0 if decelerate else 1.0) * ta_s):
        raise ValueError(f"SLS segment needs ta > 0 and tm >= {'2' if decelerate else '1'} ta "
                         f"(ta = {ta_s} s, tm = {tm_s} s)")
    y0, v0, yf = (np.asarray(x, dtype=float) for x in (y0, v0, yf))
    w = math.pi / ta_s
    distance = yf - y0
    if decelerate:
        b1 = (distance - v0 * ta_s / 2) / (tm_s - ta_s)
    else:
        b1 = (distance - v0 * ta_s / 2) / (tm_s - ta_s / 2)
    coeffs = np.empty((len(y0), 8))
    coeffs[:, Y0] = y0
    coeffs[:, A1] = (v0 + b1) / 2
    coeffs[:, A2] = (b1 - v0) / (2 * w)
    coeffs[:, B1] = b1
    coeffs[:, T_START] = 0.0
    coeffs[:, TA] = ta_s
    coeffs[:, TM] = tm_s
    coeffs[:, DECEL] = 1.0 if decelerate else 0.0
    return coeffs


@njit(cache=True)
def sls_evaluate_into(segments, t, pos, vel, acc):
    """Position, velocity, acceleration at time t of a chain of segments (n_seg, n_joints, 8).

    Before the start: the first point at rest; after the end: the last point, holding.
    """
    n_seg = segments.shape[0]
    k = 0
    while k < n_seg - 1 and t >= segments[k + 1, 0, T_START]:
        k += 1
    for j in range(segments.shape[1]):
        c = segments[k, j]
        ta = c[TA]
        tm = c[TM]
        w = math.pi / ta
        tau = t - c[T_START]
        if tau < 0.0:
            tau = 0.0
        if tau > tm:
            tau = tm
        if tau < ta:                                               # eq. 11.1
            pos[j] = c[Y0] + c[A1] * tau - c[A2] * math.sin(w * tau)
            vel[j] = c[A1] - c[A2] * w * math.cos(w * tau)
            acc[j] = c[A2] * w * w * math.sin(w * tau)
        elif c[DECEL] == 0.0 or tau < tm - ta:                     # eq. 11.2
            pos[j] = c[Y0] + c[A1] * ta + c[B1] * (tau - ta)
            vel[j] = c[B1]
            acc[j] = 0.0
        else:                                                      # eq. 11.3
            tp = tau - (tm - ta)
            c1 = 0.5 * c[B1]
            c2 = c1 / w
            c0 = c[Y0] + c[A1] * ta + c[B1] * (tm - 2.0 * ta)
            pos[j] = c0 + c1 * tp + c2 * math.sin(w * tp)
            vel[j] = c1 + c2 * w * math.cos(w * tp)
            acc[j] = -c2 * w * w * math.sin(w * tp)
        if t >= c[T_START] + tm and k == n_seg - 1 and c[DECEL] == 1.0:
            vel[j] = 0.0
            acc[j] = 0.0


@dataclass
class JointTrajectory:
    """A chain of SLS segments in joint space; evaluate_into is allocation-free."""
    segments: np.ndarray              # (n_seg, n_joints, 8)
    step: bool = False                # a step reference (`hold_at`): a setpoint held, no speed

    @property
    def duration_s(self) -> float:
        last = self.segments[-1, 0]
        return float(last[T_START] + last[TM])

    def evaluate_into(self, t: float, pos, vel, acc) -> None:
        sls_evaluate_into(self.segments, t, pos, vel, acc)

    def sample(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.segments.shape[1]
        out = np.empty((3, len(times), n))
        for k, t in enumerate(times):
            sls_evaluate_into(self.segments, float(t), out[0, k], out[1, k], out[2, k])
        return out[0], out[1], out[2]


def through_points(points, ta_s, tm_s, start_velocity=None, end_at_rest: bool = True) -> JointTrajectory:
    """Multi-point SLS through points (n_points, n_joints), at rest at the last point (or,
    `end_at_rest` False, reaching it as an intermediate point: a chain with more to come).

    ta_s and tm_s are each one value for every segment or one per segment.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or len(points) < 2:
        raise ValueError("a trajectory needs at least two points")
    n_seg = len(points) - 1
    durations = np.broadcast_to(np.asarray(tm_s, dtype=float), (n_seg,))
    accel_times = np.broadcast_to(np.asarray(ta_s, dtype=float), (n_seg,))
    velocity = np.zeros(points.shape[1]) if start_velocity is None else np.asarray(start_velocity, float)
    segments = np.empty((n_seg, points.shape[1], 8))
    start = 0.0
    for k in range(n_seg):
        last = end_at_rest and k == n_seg - 1
        segments[k] = sls_coefficients(points[k], velocity, points[k + 1], float(accel_times[k]),
                                       float(durations[k]), last)
        segments[k, :, T_START] = start
        velocity = segments[k, :, B1]
        start += float(durations[k])
    return JointTrajectory(segments)


def hold_at(point, duration_s: float) -> JointTrajectory:
    """A step reference: jump to `point` (n_joints) and hold it for `duration_s`, at rest."""
    coeffs = np.zeros((1, len(point), 8))
    coeffs[0, :, Y0] = point
    coeffs[0, :, TA] = duration_s / 2.0
    coeffs[0, :, TM] = duration_s
    coeffs[0, :, DECEL] = 1.0
    return JointTrajectory(coeffs, step=True)
