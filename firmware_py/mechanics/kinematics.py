"""Inverse, direct and instantaneous kinematics of the 6-UPS (thesis chapter 9).

Pose q = [r, p]: r the platform origin in the base frame (m), p unit Euler parameters.
Leg i runs from the universal-joint centre a_i (base) to the spherical-joint centre
B_i = r + R(p) b_i (platform); its length L_i is the actuator's joint coordinate.

Two flavours of every function: vectorised NumPy for sweeps (`*_batch`), and numba
kernels (`*_into`) that write into caller-owned arrays and allocate nothing, for the loop.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.mechanics.geometry import N_LEGS, Geometry
from firmware_py.mechanics.rotation import g_matrix_into, quat_to_matrix, quat_to_matrix_into

# -- inverse kinematics ----------------------------------------------------------------


def ik_batch(geometry: Geometry, positions_m: np.ndarray, quats: np.ndarray):
    """L_i = || r + R b_i - a_i || (eq. 9.1) for N poses: lengths (N, 6), unit legs (N, 6, 3)."""
    positions_m = np.atleast_2d(np.asarray(positions_m, dtype=float))
    rot = quat_to_matrix(np.atleast_2d(quats))
    platform_world = np.einsum("nij,kj->nki", rot, geometry.platform_anchor_m)
    legs = positions_m[:, None, :] + platform_world - geometry.base_anchor_m[None, :, :]
    lengths = np.linalg.norm(legs, axis=2)
    return lengths, legs / lengths[..., None]


@njit(cache=True)
def ik_into(base, platform, r, p, rot, platform_world, lengths, units):
    """In-place IK (eq. 9.1): lengths (6,), unit leg vectors (6, 3), R b_i (6, 3) for Jx/ID."""
    quat_to_matrix_into(p, rot)
    for i in range(base.shape[0]):
        for k in range(3):
            platform_world[i, k] = rot[k, 0] * platform[i, 0] + rot[k, 1] * platform[i, 1] + rot[k, 2] * platform[i, 2]
        lx = r[0] + platform_world[i, 0] - base[i, 0]
        ly = r[1] + platform_world[i, 1] - base[i, 1]
        lz = r[2] + platform_world[i, 2] - base[i, 2]
        length = math.sqrt(lx * lx + ly * ly + lz * lz)
        lengths[i] = length
        units[i, 0] = lx / length
        units[i, 1] = ly / length
        units[i, 2] = lz / length


# -- instantaneous kinematics ------------------------------------------------------------


def jacobian_batch(geometry: Geometry, positions_m: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """Jx (eq. 9.27) for N poses, shape (N, 6, 6): row i = [u_i^T, (R b_i x u_i)^T].

    Columns are ordered for the twist [v; w] (linear velocity of the platform origin, then
    angular velocity), so that Jx [v; w] = dL/dt. Eq. 9.27 orders the twist [w; v]; the
    two differ by a column permutation, so det differs only in sign.
    """
    _, units = ik_batch(geometry, positions_m, quats)
    rot = quat_to_matrix(np.atleast_2d(quats))
    platform_world = np.einsum("nij,kj->nki", rot, geometry.platform_anchor_m)
    return np.concatenate([units, np.cross(platform_world, units)], axis=2)


@njit(cache=True)
def jacobian_into(units, platform_world, out):
    """Jx (eq. 9.27) from the IK's unit legs and R b_i: out (6, 6), twist order [v; w]."""
    for i in range(units.shape[0]):
        ux, uy, uz = units[i, 0], units[i, 1], units[i, 2]
        bx, by, bz = platform_world[i, 0], platform_world[i, 1], platform_world[i, 2]
        out[i, 0] = ux
        out[i, 1] = uy
        out[i, 2] = uz
        out[i, 3] = by * uz - bz * uy
        out[i, 4] = bz * ux - bx * uz
        out[i, 5] = bx * uy - by * ux


def condition_index_batch(geometry: Geometry, jacobians: np.ndarray) -> np.ndarray:
    """1 / cond(Jx) with the rotation columns scaled by the platform radius (0 = singular)."""
    scaled = jacobians.copy()
    scaled[..., 3:] /= geometry.characteristic_length_m
    singular_values = np.linalg.svd(scaled, compute_uv=False)
    return singular_values[..., -1] / singular_values[..., 0]


# -- direct kinematics (chapter 9.4) ------------------------------------------------------

DK_TOLERANCE_M = 1e-11          # ||Phi|| below this ends the iteration (leg lengths, metres)
DK_MAX_ITERATIONS = 100
DK_MAX_STEP_QUAT = 1.0          # largest Euler-parameter change per iteration (see dk_solve_into)


@njit(cache=True)
def _cholesky_solve_into(a, b, out):
    """Solve a x = b for symmetric positive-definite a (6x6), in place in `a`; False if singular."""
    n = a.shape[0]
    for j in range(n):
        s = a[j, j]
        for k in range(j):
            s -= a[j, k] * a[j, k]
        if not s > 1e-300:
            return False
        d = math.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d
    for i in range(n):                    # L y = b
        s = b[i]
        for k in range(i):
            s -= a[i, k] * out[k]
        out[i] = s / a[i, i]
    for i in range(n - 1, -1, -1):        # L^T x = y
        s = out[i]
        for k in range(i + 1, n):
            s -= a[k, i] * out[k]
        out[i] = s / a[i, i]
    return True


@njit(cache=True)
def constraint_into(base, platform, lengths, q, rot, platform_world, units, phi):
    """Phi_i(q) = ||r + R b_i - a_i|| - L_i (eq. 9.4-9.6); returns ||Phi||."""
    ik_into(base, platform, q[0:3], q[3:7], rot, platform_world, phi, units)
    norm2 = 0.0
    for i in range(base.shape[0]):
        phi[i] -= lengths[i]
        norm2 += phi[i] * phi[i]
    return math.sqrt(norm2)


@njit(cache=True)
def constraint_jacobian_into(platform, q, rot, units, gmat, jac):
    """Phi_q (eq. 9.12), 6x7: row i = [n_i^T, -2 n_i^T R b_i~ G] with n_i the unit leg.

    (The thesis writes the leg vector from the platform side, hence its opposite sign.)
    """
    g_matrix_into(q[3:7], gmat)
    for i in range(platform.shape[0]):
        n0, n1, n2 = units[i, 0], units[i, 1], units[i, 2]
        jac[i, 0] = n0
        jac[i, 1] = n1
        jac[i, 2] = n2
        # m = R^T n, then -2 n^T R b~ G = -2 m^T b~ G = 2 (b x m)^T G
        m0 = rot[0, 0] * n0 + rot[1, 0] * n1 + rot[2, 0] * n2
        m1 = rot[0, 1] * n0 + rot[1, 1] * n1 + rot[2, 1] * n2
        m2 = rot[0, 2] * n0 + rot[1, 2] * n1 + rot[2, 2] * n2
        bx, by, bz = platform[i, 0], platform[i, 1], platform[i, 2]
        c0 = by * m2 - bz * m1
        c1 = bz * m0 - bx * m2
        c2 = bx * m1 - by * m0
        for j in range(4):
            jac[i, 3 + j] = 2.0 * (c0 * gmat[0, j] + c1 * gmat[1, j] + c2 * gmat[2, j])


@njit(cache=True)
def dk_solve_into(base, platform, lengths, q, tolerance, max_iterations, max_step_quat,
                  rot, platform_world, units, phi, gmat, jac, normal, y, step, status):
    """Newton-Raphson direct kinematics (chapter 9.4, Fig. 9.8), in place on q (7,).

    q holds the initial guess and receives the solution. The step is the Moore-Penrose
    pseudo-inverse of the 6x7 Phi_q, computed as Phi_q^T (Phi_q Phi_q^T)^-1 Phi (full row
    rank), followed by p <- p / ||p||. status = [iterations, ||Phi||, converged (0/1)].
    """
    iterations = 0
    residual = constraint_into(base, platform, lengths, q, rot, platform_world, units, phi)
    converged = residual < tolerance
    while not converged and iterations < max_iterations and math.isfinite(residual):
        constraint_jacobian_into(platform, q, rot, units, gmat, jac)
        for a in range(6):                                # Phi_q Phi_q^T
            for b in range(a + 1):
                s = 0.0
                for k in range(7):
                    s += jac[a, k] * jac[b, k]
                normal[a, b] = s
                normal[b, a] = s
        if not _cholesky_solve_into(normal, phi, y):
            break                                         # singular Jacobian: no step
        for k in range(7):                                # step = Phi_q^+ Phi
            s = 0.0
            for a in range(6):
                s += jac[a, k] * y[a]
            step[k] = s
        # Step cap: from a poor guess the full step in Euler parameters can exceed the
        # unit sphere's scale and land in another assembly mode; bounding it (the
        # direction is kept) raises the convergence from q25 and q50 guesses.
        dp = math.sqrt(step[3] * step[3] + step[4] * step[4] + step[5] * step[5] + step[6] * step[6])
        scale = 1.0 if dp <= max_step_quat else max_step_quat / dp
        for k in range(7):                                # q <- q - Phi_q^+ Phi
            q[k] -= scale * step[k]
        pn = math.sqrt(q[3] * q[3] + q[4] * q[4] + q[5] * q[5] + q[6] * q[6])
        for k in range(3, 7):                             # p <- p / ||p||
            q[k] /= pn
        iterations += 1
        residual = constraint_into(base, platform, lengths, q, rot, platform_world, units, phi)
        converged = residual < tolerance
    if q[3] < 0.0:                                        # one sign for the same rotation
        for k in range(3, 7):
            q[k] = -q[k]
    status[0] = iterations
    status[1] = residual
    status[2] = 1.0 if converged else 0.0


class DirectKinematics:
    """Direct kinematics with its work arrays allocated once; warm-started by default.

    `solve(lengths)` starts from the previous solution (or `guess` when given), writes the
    pose into `self.pose` (7,) and returns the number of iterations; `residual_m` and
    `converged` describe the last solve. Nothing is allocated per call.

    A solve that does not converge from the warm start is tried once more from home; if
    that fails too, `pose` goes back to the last converged one. A failed Newton iterate is
    no start: once the reference ran away while the sensors were dead (the Kalman filter
    predicting without measurements), every later warm start diverged from it and the
    controller faulted SINGULARITY after each RESET.
    """

    def __init__(self, geometry: Geometry, tolerance_m: float = DK_TOLERANCE_M,
                 max_iterations: int = DK_MAX_ITERATIONS, max_step_quat: float = DK_MAX_STEP_QUAT):
        self.base = np.ascontiguousarray(geometry.base_anchor_m)
        self.platform = np.ascontiguousarray(geometry.platform_anchor_m)
        self.tolerance_m = float(tolerance_m)
        self.max_iterations = int(max_iterations)
        self.max_step_quat = float(max_step_quat)
        self.pose = np.zeros(7)
        self.pose[0:3] = geometry.home_position_m
        self.pose[3] = 1.0
        self.home = self.pose.copy()
        self.last_good = self.pose.copy()
        self.status = np.zeros(3)
        self._rot = np.empty((3, 3))
        self._platform_world = np.empty((N_LEGS, 3))
        self._units = np.empty((N_LEGS, 3))
        self._phi = np.empty(N_LEGS)
        self._gmat = np.empty((3, 4))
        self._jac = np.empty((N_LEGS, 7))
        self._normal = np.empty((N_LEGS, N_LEGS))
        self._y = np.empty(N_LEGS)
        self._step = np.empty(7)

    def reset(self) -> None:
        self.pose[:] = self.home
        self.last_good[:] = self.home

    def solve(self, lengths_m: np.ndarray, guess: np.ndarray | None = None, fallback: bool = True) -> int:
        if guess is not None:
            self.pose[:] = guess
        iterations = self._newton(lengths_m)
        if not fallback:                 # the bare Newton solve (dk_eval measures its convergence)
            return iterations
        if not self.converged:
            self.pose[:] = self.home
            iterations += self._newton(lengths_m)
        if self.converged:
            self.last_good[:] = self.pose
        else:
            self.pose[:] = self.last_good
        return iterations

    def _newton(self, lengths_m: np.ndarray) -> int:
        dk_solve_into(self.base, self.platform, lengths_m, self.pose, self.tolerance_m, self.max_iterations,
                      self.max_step_quat, self._rot, self._platform_world, self._units, self._phi, self._gmat,
                      self._jac, self._normal, self._y, self._step, self.status)
        return int(self.status[0])

    @property
    def converged(self) -> bool:
        return self.status[2] == 1.0

    @property
    def residual_m(self) -> float:
        return float(self.status[1])
