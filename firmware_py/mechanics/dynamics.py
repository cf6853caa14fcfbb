"""Inverse dynamics of the 6-UPS by the principle of virtual work (thesis chapter 10.3).

State of the platform: pose (r, p), twist xd = [v; w] (velocity of the platform origin P and
angular velocity, base frame), acceleration xdd = [a; alpha]. Actuator forces tau (N,
positive extends the leg) follow from (eq. 10.5)

    Jx^T tau = W_p + sum_i W_leg,i ,

W the inertial-minus-gravity wrenches mapped to the platform twist by each body's link
Jacobian (eq. 10.3, 10.8-10.9). Each leg is two links rotating together with the universal
joint: the cylinder (centre of mass from the U centre) and the rod (from the S centre),
both with full inertia tensors in the link frame R_L = [u4, u2, u3] (eq. 10.13-10.17),
centres of mass anywhere (also off the actuator axis).

Derivation used (the thesis's eq. 10.29-10.42 are garbled in places; these are the same
kinematics written out). With l = B - A = d u3, u1 the first U axis (fixed to the base),
s = |u3 x u1|, u2 = u3 x u1 / s, u4 = u2 x u3 and the leg's angular velocity
w_L = th1' u1 + th2' u2:
    d'    = u3 . vB                                                     (eq. 10.23)
    th1'  = -(u2 . vB) / (s d),   th2' = (u4 . vB) / d                  (eq. 10.24-10.25)
    d''   = u3 . aB + d |w_L x u3|^2
    alpha_L = th1'' u1 + th2'' u2 + th1' th2' (u1 x u2), th1'', th2'' from the components
    of aB - d'' u3 - 2 d' w_L x u3 - d w_L x (w_L x u3) = d alpha_L x u3 normal to u3.
The leg's virtual power equals f_B . vB with
    f_B = F_rod + K^T (N_cyl + N_rod + rho_cyl x F_cyl + rho_rod x F_rod),
    K^T x = -u2 (u1 . x) / (s d) + u4 (u2 . x) / d   (w_L = K vB),
F = m (a_c - g), N = I alpha + w x I w; and the platform sees [f_B; R b_i x f_B].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.mechanics.geometry import N_LEGS, Geometry
from firmware_py.mechanics.kinematics import ik_into, jacobian_into


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def _inertia_terms(inertia, e1x, e1y, e1z, e2x, e2y, e2z, e3x, e3y, e3z, wx, wy, wz, ax, ay, az):
    """N = I_w alpha + w x (I_w w) with I_w = E I E^T, E = [e1 e2 e3] the link frame."""
    # body-frame components of w and alpha
    w1 = e1x * wx + e1y * wy + e1z * wz
    w2 = e2x * wx + e2y * wy + e2z * wz
    w3 = e3x * wx + e3y * wy + e3z * wz
    a1 = e1x * ax + e1y * ay + e1z * az
    a2 = e2x * ax + e2y * ay + e2z * az
    a3 = e3x * ax + e3y * ay + e3z * az
    iw1 = inertia[0, 0] * w1 + inertia[0, 1] * w2 + inertia[0, 2] * w3
    iw2 = inertia[1, 0] * w1 + inertia[1, 1] * w2 + inertia[1, 2] * w3
    iw3 = inertia[2, 0] * w1 + inertia[2, 1] * w2 + inertia[2, 2] * w3
    ia1 = inertia[0, 0] * a1 + inertia[0, 1] * a2 + inertia[0, 2] * a3
    ia2 = inertia[1, 0] * a1 + inertia[1, 1] * a2 + inertia[1, 2] * a3
    ia3 = inertia[2, 0] * a1 + inertia[2, 1] * a2 + inertia[2, 2] * a3
    g1, g2, g3 = _cross(w1, w2, w3, iw1, iw2, iw3)
    n1, n2, n3 = ia1 + g1, ia2 + g2, ia3 + g3
    return (e1x * n1 + e2x * n2 + e3x * n3, e1y * n1 + e2y * n2 + e3y * n3, e1z * n1 + e2z * n2 + e3z * n3)


@njit(cache=True, inline="always")
def _link_wrench(mass, com, inertia, e1x, e1y, e1z, e2x, e2y, e2z, e3x, e3y, e3z,
                 wx, wy, wz, ax, ay, az, ox, oy, oz, gx, gy, gz):
    """Inertial-minus-gravity force F and the moment rho x F + N of a leg link about its origin.

    Frame [e1 e2 e3] = [u4 u2 u3]; the link rotates with (w, alpha); its origin (A or B)
    accelerates by (ox, oy, oz); rho = R_L com.
    """
    px = com[0] * e1x + com[1] * e2x + com[2] * e3x
    py = com[0] * e1y + com[1] * e2y + com[2] * e3y
    pz = com[0] * e1z + com[1] * e2z + com[2] * e3z
    t1 = _cross(ax, ay, az, px, py, pz)
    t2 = _cross(wx, wy, wz, px, py, pz)
    t3 = _cross(wx, wy, wz, t2[0], t2[1], t2[2])
    fx = mass * (ox + t1[0] + t3[0] - gx)
    fy = mass * (oy + t1[1] + t3[1] - gy)
    fz = mass * (oz + t1[2] + t3[2] - gz)
    n = _inertia_terms(inertia, e1x, e1y, e1z, e2x, e2y, e2z, e3x, e3y, e3z, wx, wy, wz, ax, ay, az)
    r = _cross(px, py, pz, fx, fy, fz)
    return fx, fy, fz, n[0] + r[0], n[1] + r[1], n[2] + r[2]


@njit(cache=True)
def gauss_solve_into(matrix, rhs, lu, out, transposed):
    """Solve matrix out = rhs (or matrix^T out = rhs) by Gaussian elimination with partial
    pivoting in the scratch `lu`; returns |det(matrix)|, 0.0 when singular (out undefined)."""
    n = matrix.shape[0]
    det = 1.0
    for i in range(n):
        for j in range(n):
            lu[i, j] = matrix[j, i] if transposed else matrix[i, j]
        out[i] = rhs[i]
    for col in range(n):
        pivot = col
        best = abs(lu[col, col])
        for row in range(col + 1, n):
            if abs(lu[row, col]) > best:
                best = abs(lu[row, col])
                pivot = row
        if not best > 1e-300:
            return 0.0
        if pivot != col:
            for j in range(n):
                lu[col, j], lu[pivot, j] = lu[pivot, j], lu[col, j]
            out[col], out[pivot] = out[pivot], out[col]
        det *= lu[col, col]
        for row in range(col + 1, n):
            factor = lu[row, col] / lu[col, col]
            for j in range(col, n):
                lu[row, j] -= factor * lu[col, j]
            out[row] -= factor * out[col]
    for row in range(n - 1, -1, -1):
        s = out[row]
        for j in range(row + 1, n):
            s -= lu[row, j] * out[j]
        out[row] = s / lu[row, row]
    return abs(det)


@njit(cache=True)
def platform_wrench_into(base, platform, axis1, lengths, units, platform_world, rot,
                         masses, coms, inertias, gravity, twist, accel, wrench):
    """W = sum of inertial-minus-gravity wrenches mapped to the platform twist [v; w] (6,).

    masses (3,) = platform, cylinder, rod; coms (3, 3) rows in their body frames; inertias
    (3, 3, 3) about the centres of mass. `lengths`, `units`, `platform_world` and `rot` are
    the IK's outputs for the pose.
    """
    vx, vy, vz, wx, wy, wz = twist[0], twist[1], twist[2], twist[3], twist[4], twist[5]
    ax, ay, az, bx_, by_, bz_ = accel[0], accel[1], accel[2], accel[3], accel[4], accel[5]
    gx, gy, gz = gravity[0], gravity[1], gravity[2]
    # platform: centre of mass rho = R c_p from P
    rx = rot[0, 0] * coms[0, 0] + rot[0, 1] * coms[0, 1] + rot[0, 2] * coms[0, 2]
    ry = rot[1, 0] * coms[0, 0] + rot[1, 1] * coms[0, 1] + rot[1, 2] * coms[0, 2]
    rz = rot[2, 0] * coms[0, 0] + rot[2, 1] * coms[0, 1] + rot[2, 2] * coms[0, 2]
    t1x, t1y, t1z = _cross(bx_, by_, bz_, rx, ry, rz)
    wr = _cross(wx, wy, wz, rx, ry, rz)
    t2x, t2y, t2z = _cross(wx, wy, wz, wr[0], wr[1], wr[2])
    m = masses[0]
    fx = m * (ax + t1x + t2x - gx)
    fy = m * (ay + t1y + t2y - gy)
    fz = m * (az + t1z + t2z - gz)
    nx, ny, nz = _inertia_terms(inertias[0], rot[0, 0], rot[1, 0], rot[2, 0], rot[0, 1], rot[1, 1], rot[2, 1],
                                rot[0, 2], rot[1, 2], rot[2, 2], wx, wy, wz, bx_, by_, bz_)
    mx, my, mz = _cross(rx, ry, rz, fx, fy, fz)
    wrench[0] = fx
    wrench[1] = fy
    wrench[2] = fz
    wrench[3] = nx + mx
    wrench[4] = ny + my
    wrench[5] = nz + mz
    m1, m2 = masses[1], masses[2]
    for i in range(base.shape[0]):
        d = lengths[i]
        u3x, u3y, u3z = units[i, 0], units[i, 1], units[i, 2]
        u1x, u1y, u1z = axis1[i, 0], axis1[i, 1], axis1[i, 2]
        pbx, pby, pbz = platform_world[i, 0], platform_world[i, 1], platform_world[i, 2]
        # velocity and acceleration of B (eq. 10.18)
        c = _cross(wx, wy, wz, pbx, pby, pbz)
        vbx, vby, vbz = vx + c[0], vy + c[1], vz + c[2]
        c2 = _cross(bx_, by_, bz_, pbx, pby, pbz)
        c3 = _cross(wx, wy, wz, c[0], c[1], c[2])
        abx, aby, abz = ax + c2[0] + c3[0], ay + c2[1] + c3[1], az + c2[2] + c3[2]
        # U-joint frame (eq. 10.15-10.17)
        u2x, u2y, u2z = _cross(u3x, u3y, u3z, u1x, u1y, u1z)
        s = math.sqrt(u2x * u2x + u2y * u2y + u2z * u2z)
        u2x, u2y, u2z = u2x / s, u2y / s, u2z / s
        u4x, u4y, u4z = _cross(u2x, u2y, u2z, u3x, u3y, u3z)
        # joint rates (eq. 10.23-10.25)
        dd = u3x * vbx + u3y * vby + u3z * vbz
        th1 = -(u2x * vbx + u2y * vby + u2z * vbz) / (s * d)
        th2 = (u4x * vbx + u4y * vby + u4z * vbz) / d
        olx, oly, olz = th1 * u1x + th2 * u2x, th1 * u1y + th2 * u2y, th1 * u1z + th2 * u2z
        ou = _cross(olx, oly, olz, u3x, u3y, u3z)
        oou = _cross(olx, oly, olz, ou[0], ou[1], ou[2])
        ddd = u3x * abx + u3y * aby + u3z * abz + d * (ou[0] * ou[0] + ou[1] * ou[1] + ou[2] * ou[2])
        # d alpha_L x u3 = aB - d'' u3 - 2 d' w_L x u3 - d w_L x (w_L x u3)
        qx = (abx - ddd * u3x - 2.0 * dd * ou[0] - d * oou[0]) / d
        qy = (aby - ddd * u3y - 2.0 * dd * ou[1] - d * oou[1]) / d
        qz = (abz - ddd * u3z - 2.0 * dd * ou[2] - d * oou[2]) / d
        u12 = _cross(u1x, u1y, u1z, u2x, u2y, u2z)
        e = _cross(u12[0], u12[1], u12[2], u3x, u3y, u3z)
        k = th1 * th2
        qx, qy, qz = qx - k * e[0], qy - k * e[1], qz - k * e[2]
        th1dd = -(u2x * qx + u2y * qy + u2z * qz) / s
        th2dd = u4x * qx + u4y * qy + u4z * qz
        alx = th1dd * u1x + th2dd * u2x + k * u12[0]
        aly = th1dd * u1y + th2dd * u2y + k * u12[1]
        alz = th1dd * u1z + th2dd * u2z + k * u12[2]
        # cylinder from A (eq. 10.13, A at rest), rod from B (eq. 10.14)
        _, _, _, h1x, h1y, h1z = _link_wrench(m1, coms[1], inertias[1], u4x, u4y, u4z, u2x, u2y, u2z,
                                              u3x, u3y, u3z, olx, oly, olz, alx, aly, alz,
                                              0.0, 0.0, 0.0, gx, gy, gz)
        f2x, f2y, f2z, h2x, h2y, h2z = _link_wrench(m2, coms[2], inertias[2], u4x, u4y, u4z, u2x, u2y, u2z,
                                                    u3x, u3y, u3z, olx, oly, olz, alx, aly, alz,
                                                    abx, aby, abz, gx, gy, gz)
        # f_B = F_rod + K^T (sum of the links' moments about their origins), module docstring
        hx, hy, hz = h1x + h2x, h1y + h2y, h1z + h2z
        c_u1 = -(u1x * hx + u1y * hy + u1z * hz) / (s * d)
        c_u2 = (u2x * hx + u2y * hy + u2z * hz) / d
        fbx = f2x + c_u1 * u2x + c_u2 * u4x
        fby = f2y + c_u1 * u2y + c_u2 * u4y
        fbz = f2z + c_u1 * u2z + c_u2 * u4z
        mb = _cross(pbx, pby, pbz, fbx, fby, fbz)
        wrench[0] += fbx
        wrench[1] += fby
        wrench[2] += fbz
        wrench[3] += mb[0]
        wrench[4] += mb[1]
        wrench[5] += mb[2]


class InverseDynamics:
    """Actuator forces and task-space terms for one pose; every array allocated here, once.

    forces(r, p, twist, accel) -> self.force_n (6,): tau with Jx^T tau = W (eq. 10.5).
    task_space_terms(r, p, twist): self.mass_matrix (6x6) and self.bias (6,) so that
    W = M xdd + bias (bias holds the velocity and gravity terms, eq. 10.10-10.12), and
    self.gravity_wrench (6,) the static part alone.
    """

    def __init__(self, geometry: Geometry):
        self.base = np.ascontiguousarray(geometry.base_anchor_m)
        self.platform = np.ascontiguousarray(geometry.platform_anchor_m)
        self.axis1 = np.ascontiguousarray(geometry.universal_axis)
        self.masses = np.array([geometry.platform.mass_kg, geometry.cylinder.mass_kg, geometry.rod.mass_kg])
        self.coms = np.ascontiguousarray(np.stack([geometry.platform.com_m, geometry.cylinder.com_m,
                                                   geometry.rod.com_m]))
        self.inertias = np.ascontiguousarray(np.stack([geometry.platform.inertia_kg_m2,
                                                       geometry.cylinder.inertia_kg_m2,
                                                       geometry.rod.inertia_kg_m2]))
        self.gravity = np.array(geometry.gravity_m_s2, dtype=float)
        self.no_gravity = np.zeros(3)
        self.lengths = np.empty(N_LEGS)
        self.units = np.empty((N_LEGS, 3))
        self.platform_world = np.empty((N_LEGS, 3))
        self.rot = np.empty((3, 3))
        self.jacobian = np.empty((N_LEGS, 6))
        self.wrench = np.empty(6)
        self.force_n = np.empty(N_LEGS)
        self.mass_matrix = np.empty((6, 6))
        self.bias = np.empty(6)
        self.gravity_wrench = np.empty(6)
        self._zero6 = np.zeros(6)
        self._unit = np.zeros(6)
        self._lu = np.empty((6, 6))

    def _kinematics(self, position_m, quat) -> None:
        ik_into(self.base, self.platform, position_m, quat, self.rot, self.platform_world, self.lengths, self.units)
        jacobian_into(self.units, self.platform_world, self.jacobian)

    def _wrench(self, twist, accel, gravity, out) -> None:
        platform_wrench_into(self.base, self.platform, self.axis1, self.lengths, self.units, self.platform_world,
                             self.rot, self.masses, self.coms, self.inertias, gravity, twist, accel, out)

    def forces(self, position_m, quat, twist, accel) -> bool:
        """tau for the state; False (and NaN forces) at a singular Jx."""
        self._kinematics(position_m, quat)
        self._wrench(twist, accel, self.gravity, self.wrench)
        return self.joint_forces_from_wrench(self.wrench)

    def task_space_terms(self, position_m, quat, twist) -> None:
        self._kinematics(position_m, quat)
        self._wrench(twist, self._zero6, self.gravity, self.bias)
        self._wrench(self._zero6, self._zero6, self.gravity, self.gravity_wrench)
        for k in range(6):            # W is affine in xdd: columns from unit accelerations at rest
            self._unit[k] = 1.0
            self._wrench(self._zero6, self._unit, self.no_gravity, self.wrench)
            self.mass_matrix[:, k] = self.wrench
            self._unit[k] = 0.0

    def joint_forces_from_wrench(self, wrench) -> bool:
        """tau = Jx^-T W for the pose of the last call."""
        ok = gauss_solve_into(self.jacobian, wrench, self._lu, self.force_n, True) > 0.0
        if not ok:
            self.force_n.fill(np.nan)
        return ok
