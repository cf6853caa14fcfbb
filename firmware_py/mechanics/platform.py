"""The platform seen from the legs, every cycle (hexapod rig): pose estimate by direct
kinematics warm-started from the last cycle (chapter 9.4), gravity along each leg,
singularity proximity, and the virtual-work actuator forces along the reference
(eq. 10.5, used by the model-based controller, eq. 11.5). Arrays allocated once.
"""

from __future__ import annotations

import numpy as np

from firmware_py.mechanics.dynamics import InverseDynamics, gauss_solve_into
from firmware_py.mechanics.geometry import N_LEGS, Geometry
from firmware_py.mechanics.kinematics import DirectKinematics, ik_into, jacobian_into


class PlatformModel:
    def __init__(self, geometry: Geometry, tolerance_m: float, max_iterations: int, period_s: float):
        self.geometry = geometry
        self.period_s = period_s
        self.leg_min_m = np.array(geometry.leg_min_m)        # 0-d arrays: a Python number in a ufunc
        self._inverse_period = np.array(1.0 / period_s)       # would be converted every call
        self.dk = DirectKinematics(geometry, tolerance_m, max_iterations)
        self.ref_dk = DirectKinematics(geometry, tolerance_m, max_iterations)
        self.dynamics = InverseDynamics(geometry)
        self.lengths = np.empty(N_LEGS)
        self.ref_lengths = np.empty(N_LEGS)
        self.units = np.empty((N_LEGS, 3))
        self.platform_world = np.empty((N_LEGS, 3))
        self.rot = np.empty((3, 3))
        self.jacobian = np.empty((N_LEGS, 6))
        self.jacobian_scaled = np.empty((N_LEGS, 6))
        self.gravity_axial = np.empty(N_LEGS)
        self.minus_gravity = -np.asarray(geometry.gravity_m_s2, dtype=float)
        self._ref_units = np.empty((N_LEGS, 3))
        self._ref_world = np.empty((N_LEGS, 3))
        self._ref_rot = np.empty((3, 3))
        self._ref_lengths_ik = np.empty(N_LEGS)
        self._ref_jacobian = np.empty((N_LEGS, 6))
        self.twist = np.zeros(6)
        self.prev_twist = np.zeros(6)
        self.accel = np.zeros(6)
        self.force_n = np.zeros(N_LEGS)
        self._lu = np.empty((6, 6))
        self._zero6 = np.zeros(6)
        self._scratch6 = np.empty(6)
        self.radius = float(np.linalg.norm(geometry.platform_anchor_m[0]))
        self._inverse_radius = np.array(1.0 / self.radius)
        self.det_home = 1.0
        self.det_ratio = 1.0
        self.converged = True
        home = self.dk.home
        self.update_measured_kinematics(home[0:3], home[3:7])
        self.det_home = self._scaled_det()
        self.det_ratio = 1.0

    def _scaled_det(self) -> float:
        # rotation columns scaled by the platform radius: dimensionless, as the condition index
        self.jacobian_scaled[:, 0:3] = self.jacobian[:, 0:3]
        np.multiply(self.jacobian[:, 3:6], self._inverse_radius, out=self.jacobian_scaled[:, 3:6])
        return gauss_solve_into(self.jacobian_scaled, self._zero6, self._lu, self._scratch6, False)

    def update_measured_kinematics(self, position_m, quat) -> None:
        ik_into(self.dk.base, self.dk.platform, position_m, quat, self.rot, self.platform_world, self.lengths,
                self.units)
        jacobian_into(self.units, self.platform_world, self.jacobian)
        np.dot(self.units, self.minus_gravity, out=self.gravity_axial)   # g along each leg, + opposes extension
        self.det_ratio = self._scaled_det() / self.det_home

    def estimate(self, strokes_m) -> bool:
        """DK from the measured strokes (warm start); leg axes, gravity per leg, det ratio."""
        np.add(strokes_m, self.leg_min_m, out=self.lengths)
        self.dk.solve(self.lengths)
        self.converged = self.dk.converged
        if self.converged:
            self.update_measured_kinematics(self.dk.pose[0:3], self.dk.pose[3:7])
        return self.converged

    def reset_reference(self, strokes_m) -> None:
        np.add(strokes_m, self.leg_min_m, out=self.ref_lengths)
        self.ref_dk.solve(self.ref_lengths, self.dk.pose)
        self.prev_twist.fill(0.0)

    def reference_forces(self, strokes_m, stroke_rates) -> bool:
        """Actuator forces of eq. 10.5 along the reference: pose by DK of the reference
        lengths, twist from Jx xd = L', acceleration by differencing the twist over one
        period (the reference is smooth: the SLS acceleration is continuous)."""
        np.add(strokes_m, self.leg_min_m, out=self.ref_lengths)
        self.ref_dk.solve(self.ref_lengths)
        pose = self.ref_dk.pose
        ik_into(self.dk.base, self.dk.platform, pose[0:3], pose[3:7], self._ref_rot, self._ref_world,
                self._ref_lengths_ik, self._ref_units)
        jacobian_into(self._ref_units, self._ref_world, self._ref_jacobian)
        self.prev_twist[:] = self.twist
        if gauss_solve_into(self._ref_jacobian, stroke_rates, self._lu, self.twist, False) == 0.0:
            self.force_n.fill(np.nan)
            return False
        np.subtract(self.twist, self.prev_twist, out=self.accel)
        np.multiply(self.accel, self._inverse_period, out=self.accel)
        ok = self.dynamics.forces(pose[0:3], pose[3:7], self.twist, self.accel)
        self.force_n[:] = self.dynamics.force_n
        return ok and self.ref_dk.converged
