"""Euler parameters (unit quaternions, scalar first: p = [e0, e1, e2, e3]) and rotations.

Appendix C of the thesis: R = E G^T with E = [-e, e~ + e0 I], G = [-e, -e~ + e0 I]; a
small change of p rotates a body-fixed vector s' by ds = -2 R s'~ G dp (eq. C.11).
Roll-pitch-yaw is R = Rz(yaw) Ry(pitch) Rx(roll), as on the bus (IMU_ATTITUDE).

The `*_into` functions are numba kernels that write into caller-owned arrays (the
controller's loop calls them); the plain functions are vectorised NumPy for sweeps.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def quat_to_matrix_into(p, out):
    """R(p) = (2 e0^2 - 1) I + 2 (e e^T + e0 e~) (Appendix C); p need not be normalised."""
    e0, e1, e2, e3 = p[0], p[1], p[2], p[3]
    s = 1.0 / (e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    out[0, 0] = 1.0 - 2.0 * s * (e2 * e2 + e3 * e3)
    out[0, 1] = 2.0 * s * (e1 * e2 - e0 * e3)
    out[0, 2] = 2.0 * s * (e1 * e3 + e0 * e2)
    out[1, 0] = 2.0 * s * (e1 * e2 + e0 * e3)
    out[1, 1] = 1.0 - 2.0 * s * (e1 * e1 + e3 * e3)
    out[1, 2] = 2.0 * s * (e2 * e3 - e0 * e1)
    out[2, 0] = 2.0 * s * (e1 * e3 - e0 * e2)
    out[2, 1] = 2.0 * s * (e2 * e3 + e0 * e1)
    out[2, 2] = 1.0 - 2.0 * s * (e1 * e1 + e2 * e2)


@njit(cache=True)
def rpy_to_matrix_into(roll, pitch, yaw, out):
    """R = Rz(yaw) Ry(pitch) Rx(roll), the bus's roll-pitch-yaw (IMU_ATTITUDE)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    out[0, 0] = cy * cp
    out[0, 1] = cy * sp * sr - sy * cr
    out[0, 2] = cy * sp * cr + sy * sr
    out[1, 0] = sy * cp
    out[1, 1] = sy * sp * sr + cy * cr
    out[1, 2] = sy * sp * cr - cy * sr
    out[2, 0] = -sp
    out[2, 1] = cp * sr
    out[2, 2] = cp * cr


@njit(cache=True)
def angle_between_matrices(a, b):
    """Angle of the rotation a^T b [rad]: trace(a^T b) = 1 + 2 cos(angle)."""
    trace = 0.0
    for i in range(3):
        for j in range(3):
            trace += a[i, j] * b[i, j]
    c = min(max(0.5 * (trace - 1.0), -1.0), 1.0)
    return np.arccos(c)


@njit(cache=True)
def g_matrix_into(p, out):
    """G = [-e, -e~ + e0 I] (3x4), so that the body-frame virtual rotation is 2 G dp (eq. C.10)."""
    e0, e1, e2, e3 = p[0], p[1], p[2], p[3]
    out[0, 0] = -e1
    out[0, 1] = e0
    out[0, 2] = e3
    out[0, 3] = -e2
    out[1, 0] = -e2
    out[1, 1] = -e3
    out[1, 2] = e0
    out[1, 3] = e1
    out[2, 0] = -e3
    out[2, 1] = e2
    out[2, 2] = -e1
    out[2, 3] = e0


def quat_to_matrix(p: np.ndarray) -> np.ndarray:
    """Vectorised R(p) for p of shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    p = p / np.linalg.norm(p, axis=-1, keepdims=True)
    e0, e1, e2, e3 = np.moveaxis(p, -1, 0)
    rot = np.empty(p.shape[:-1] + (3, 3))
    rot[..., 0, 0] = 1 - 2 * (e2 * e2 + e3 * e3)
    rot[..., 0, 1] = 2 * (e1 * e2 - e0 * e3)
    rot[..., 0, 2] = 2 * (e1 * e3 + e0 * e2)
    rot[..., 1, 0] = 2 * (e1 * e2 + e0 * e3)
    rot[..., 1, 1] = 1 - 2 * (e1 * e1 + e3 * e3)
    rot[..., 1, 2] = 2 * (e2 * e3 - e0 * e1)
    rot[..., 2, 0] = 2 * (e1 * e3 - e0 * e2)
    rot[..., 2, 1] = 2 * (e2 * e3 + e0 * e1)
    rot[..., 2, 2] = 1 - 2 * (e1 * e1 + e2 * e2)
    return rot


def rpy_to_quat(roll, pitch, yaw) -> np.ndarray:
    """Quaternion of R = Rz(yaw) Ry(pitch) Rx(roll); broadcasts."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(yaw) / 2), np.sin(np.asarray(yaw) / 2)
    return np.stack([cr * cp * cy + sr * sp * sy,
                     sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy], axis=-1)


def quat_to_rpy(p) -> np.ndarray:
    """(roll, pitch, yaw) of R(p) = Rz Ry Rx; pitch in [-pi/2, pi/2]."""
    rot = quat_to_matrix(p)
    roll = np.arctan2(rot[..., 2, 1], rot[..., 2, 2])
    pitch = np.arcsin(np.clip(-rot[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(rot[..., 1, 0], rot[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def axis_angle_to_quat(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = np.asarray(angle, dtype=float)[..., None] / 2
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def quat_to_axis_angle(p) -> tuple[np.ndarray, np.ndarray]:
    """(unit axis, angle in [0, pi]); the axis is x when the angle is 0."""
    p = np.asarray(p, dtype=float)
    p = p / np.linalg.norm(p, axis=-1, keepdims=True)
    p = np.where(p[..., :1] < 0, -p, p)                 # q and -q: pick e0 >= 0
    sin_half = np.linalg.norm(p[..., 1:], axis=-1)
    angle = 2 * np.arctan2(sin_half, p[..., 0])
    safe = sin_half > 1e-15
    axis = np.where(safe[..., None], p[..., 1:] / np.where(safe, sin_half, 1.0)[..., None],
                    np.array([1.0, 0.0, 0.0]))
    return axis, angle


@njit(cache=True)
def rotation_vector_between_into(p, q, out) -> None:
    """out = rotation vector of R(p) R(q)^T (the rotation from q to p, base frame): the
    relative quaternion p conj(q) taken the shorter way round."""
    aw, ax, ay, az = p[0], p[1], p[2], p[3]
    bw, bx, by, bz = q[0], -q[1], -q[2], -q[3]
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    norm = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(norm, w) / norm if norm > 1e-12 else 2.0
    out[0], out[1], out[2] = scale * x, scale * y, scale * z


def quat_multiply(a, b) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a0, a1, a2, a3 = np.moveaxis(a, -1, 0)
    b0, b1, b2, b3 = np.moveaxis(b, -1, 0)
    return np.stack([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
                     a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
                     a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
                     a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0], axis=-1)


def rotation_angle_between(p, q) -> np.ndarray:
    """Angle of the rotation taking R(q) to R(p), in [0, pi]; insensitive to the sign of p, q.

    From the relative quaternion conj(q) p as 2 atan2(|vector part|, |scalar part|), which
    keeps full precision for tiny angles (arccos of a dot product would not).
    """
    q = np.asarray(q, dtype=float)
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    rel = quat_multiply(conj, p)
    return 2 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))
