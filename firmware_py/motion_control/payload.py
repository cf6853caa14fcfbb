"""The payload on the platform, identified from the load cells (beyond the thesis: chapter
7.5.3's recursive least squares, from one leg's load mass to the platform's payload).

A point mass m at c in the platform's frame adds to eq. 10.5's wrench, at the platform's
acceleration a (its rotation's terms left out),
    W_payload = [ m (a - g) ;  (R m c) x (a - g) ],
linear in theta = (m, delta) with m c = m c0 + delta about a prior centre of mass c0 (the
declared payload's: the platform's own): W_payload = Phi(R, a, c0) theta. The rods' load
cells read the actuators' forces less the rods' weight along the legs; the bare platform's
model (the geometry without any payload) gives the rest, so
    y = Jx^T (F_cells - (tau_bare(pose, a) - m_rod g_axial)) = Phi theta + noise,
six rows per cycle, one RLS (exponential forgetting) over theta. With the platform level and
still, gravity sees m and the centre of mass's x and y; its height needs a tilt or an
acceleration, and stays at the prior's until one shows it. The platform is taken as still
(a = 0): a sample is taken only while every leg's reference accelerates less than the gate
(the SLS's blends are not followed exactly) and every load cell is fresh; a swing about the
reference averages out over the forgetting's memory (~2 s). Allocation-free.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.mechanics.dynamics import InverseDynamics

N_THETA = 4                      # m, h_x, h_y, h_z


@njit(cache=True)
def payload_regressor_into(rot, accel, gravity, com_prior, phi) -> None:
    """Phi (6, 4) with W_payload = Phi theta, theta = (m, delta), m c = m c0 + delta, c and the
    prior c0 in the platform's frame."""
    dx, dy, dz = accel[0] - gravity[0], accel[1] - gravity[1], accel[2] - gravity[2]
    for r in range(6):
        for k in range(N_THETA):
            phi[r, k] = 0.0
    # (R v) x d = -d x (R v): row r of -skew(d) R, for v = delta (columns 1-3) and v = c0 (column 0)
    for k in range(3):
        phi[3, 1 + k] = dz * rot[1, k] - dy * rot[2, k]
        phi[4, 1 + k] = dx * rot[2, k] - dz * rot[0, k]
        phi[5, 1 + k] = dy * rot[0, k] - dx * rot[1, k]
    phi[0, 0], phi[1, 0], phi[2, 0] = dx, dy, dz
    for r in range(3, 6):
        phi[r, 0] = phi[r, 1] * com_prior[0] + phi[r, 2] * com_prior[1] + phi[r, 3] * com_prior[2]


@njit(cache=True)
def rls_rows_step(theta, p, phi, y, forgetting, p_max, mass_max, reach, pk, gain) -> None:
    """One cycle's rows of y = Phi theta in turn (forgetting applied once, at the last); P's
    diagonal capped at p_max, the mass kept in [0, mass_max], the centre of mass within
    `reach` of the prior on each axis."""
    rows, n = phi.shape
    for r in range(rows):
        for i in range(n):                                   # pk = P phi_r
            s = 0.0
            for j in range(n):
                s += p[i, j] * phi[r, j]
            pk[i] = s
        lam = forgetting if r == rows - 1 else 1.0
        denominator = lam
        innovation = y[r]
        for i in range(n):
            denominator += phi[r, i] * pk[i]
            innovation -= phi[r, i] * theta[i]
        for i in range(n):
            gain[i] = pk[i] / denominator
            theta[i] += gain[i] * innovation
        for i in range(n):                                   # P = (P - K phi^T P) / lambda
            for j in range(n):
                p[i, j] = (p[i, j] - gain[i] * pk[j]) / lam
    for i in range(n):
        if p[i, i] > p_max:
            scale = math.sqrt(p_max / p[i, i])
            for j in range(n):
                p[i, j] *= scale
                p[j, i] *= scale
    theta[0] = min(max(theta[0], 0.0), mass_max)
    for k in range(1, n):                                    # the centre of mass within reach of the prior
        theta[k] = min(max(theta[k], -theta[0] * reach), theta[0] * reach)


@njit(cache=True)
def innovation_beyond(phi, theta, y, limit) -> bool:
    """Whether a row of y - Phi theta exceeds `limit` (N, N m)."""
    for r in range(phi.shape[0]):
        s = y[r]
        for k in range(phi.shape[1]):
            s -= phi[r, k] * theta[k]
        if abs(s) > limit:
            return True
    return False


@njit(cache=True)
def measured_wrench_into(jacobian, force_measured, force_bare, rod_mass_kg, gravity_axial, out) -> None:
    """out = Jx^T (F_cells - (tau_bare - m_rod g_axial)): a load cell on the rod reads the
    actuator's force less the rod's own weight along the leg."""
    for k in range(6):
        s = 0.0
        for leg in range(jacobian.shape[0]):
            s += jacobian[leg, k] * (force_measured[leg] - force_bare[leg] + rod_mass_kg * gravity_axial[leg])
        out[k] = s


@njit(cache=True)
def with_payload_into(masses, coms, bare_mass_kg, bare_com, com_prior, theta) -> None:
    """An inverse dynamics' platform body (masses[0], coms[0]) as the bare platform plus the
    estimate: mass m_p + m, centre of mass (m_p c_p + m c0 + delta) / (m_p + m)."""
    total = bare_mass_kg + theta[0]
    masses[0] = total
    for k in range(3):
        coms[0, k] = (bare_mass_kg * bare_com[k] + theta[0] * com_prior[k] + theta[1 + k]) / total


class PayloadEstimator:
    """theta = (m, m c) from the load cells; the bare platform's model is its own."""

    def __init__(self, bare_geometry, cfg_payload, declared_kg: float, declared_com_m):
        self.cfg = cfg_payload
        self.bare = InverseDynamics(bare_geometry)
        self.gravity = np.asarray(bare_geometry.gravity_m_s2, dtype=float)
        self.theta = np.zeros(N_THETA)
        self.p = np.zeros((N_THETA, N_THETA))
        self.phi = np.zeros((6, N_THETA))
        self.y = np.zeros(6)
        self._pk, self._gain = np.zeros(N_THETA), np.zeros(N_THETA)
        self._zero6 = np.zeros(6)
        self._accel6 = np.zeros(6)
        self.declared = (declared_kg, np.asarray(declared_com_m, dtype=float).copy())
        self.bare_mass_kg = float(bare_geometry.platform.mass_kg)
        self.rod_mass_kg = float(bare_geometry.rod.mass_kg)
        self.bare_com = np.asarray(bare_geometry.platform.com_m, dtype=float).copy()
        self.samples = 0
        self.reset()

    def reset(self) -> None:
        """Back to the declared payload, as uncertain as configured."""
        self.theta[0] = self.declared[0]
        self.theta[1:4] = 0.0                            # at the prior
        self.p[:] = 0.0
        for i in range(N_THETA):
            self.p[i, i] = self.cfg.covariance_initial
        self.samples = 0

    def update(self, position_m, quat, rot, jacobian, gravity_axial, force_measured, accel_ref) -> bool:
        """One cycle's sample (the caller has gated it): True when taken."""
        self._accel6[0:3] = accel_ref
        if not self.bare.forces(position_m, quat, self._zero6, self._accel6):
            return False
        measured_wrench_into(jacobian, force_measured, self.bare.force_n, self.rod_mass_kg, gravity_axial, self.y)
        payload_regressor_into(rot, accel_ref, self.gravity, self.declared[1], self.phi)
        cfg = self.cfg
        if innovation_beyond(self.phi, self.theta, self.y, cfg.innovation_max_n):
            return False                             # a load cell's fault, not a payload
        rls_rows_step(self.theta, self.p, self.phi, self.y, cfg.forgetting, cfg.covariance_max, cfg.mass_max_kg,
                      cfg.com_reach_m, self._pk, self._gain)
        self.samples += 1
        return True

    def apply_to(self, dynamics) -> None:
        """The estimate into an inverse dynamics (its arrays, in place)."""
        with_payload_into(dynamics.masses, dynamics.coms, self.bare_mass_kg, self.bare_com, self.declared[1],
                          self.theta)

    @property
    def mass_kg(self) -> float:
        return float(self.theta[0])

    def com_into(self, out) -> bool:
        """The centre of mass (platform frame) into `out`; False (out untouched) while the mass
        is too small to place it."""
        m = self.theta[0]
        if m < self.cfg.com_mass_min_kg:
            return False
        for k in range(3):
            out[k] = self.declared[1][k] + self.theta[1 + k] / m
        return True
