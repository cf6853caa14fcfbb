"""The rig the controller drives, as an object: what differs between the test bench's one
leg and the hexapod's six (their strokes and positions, the mass each leg moves, the
waypoint check, the computed-torque form, the platform's pose estimate and its checks, the
controlled stop, the identification tests), so the controller's cycle has no branch on it.

- `TestbenchModel` (chapters 5-7): one actuator; a waypoint's Z is its stroke.
- `HexapodModel` (chapters 9-11): six legs; waypoints are platform poses, the pose is
  estimated by direct kinematics every cycle and checked against singularities and the IMU.
"""

from __future__ import annotations

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.mechanics.dynamics import gauss_solve_into
from firmware_py.mechanics.geometry import Geometry, default_geometry
from firmware_py.motion_control.computed_torque import YAW, ComputedTorque, LegComputedTorque
from firmware_py.motion_control.excitation import IdentificationSignal
from firmware_py.motion_control.payload import PayloadEstimator
from firmware_py.motion_control.yaw_fusion import YawFusion, quat_yaw, wrapped
from firmware_py.supervision.capacity import leg_capacity
from firmware_py.supervision.monitors import all_set, any_beyond, pose_beyond
from firmware_py.supervision.plausibility import AttitudeCrossCheck
from firmware_py.supervision.waypoints import HexapodCheck, TestbenchCheck
from physics.constants import GRAVITY_M_S2
from protocol.enums import Fault
from protocol.nodes import RIGS


class TestbenchModel:
    """The single actuator lifting the guide's slide and its load."""

    __test__ = False             # not a pytest class despite the name
    name = "testbench"
    n = 1
    n_nodes = 1                  # its leg node
    stop_cycles = 0              # a fault holds the one valve at once
    platform = None
    geometry = None

    def __init__(self, cfg: ControllerConfig, period_s: float):
        self.stroke_m = cfg.actuator.stroke_m
        self.home_strokes = np.full(1, cfg.testbench.home_m)
        self.park_strokes = np.full(1, cfg.testbench.park_m)
        self.moving_mass_kg, self.mass_offset_kg = cfg.actuator.moving_mass_kg, cfg.testbench.slide_mass_kg
        self.rod_mass_kg = cfg.actuator.moving_mass_kg
        self.guide_friction = (cfg.testbench.guide_coulomb_n, cfg.testbench.guide_viscous_ns_m)
        self.kp_factor = self.ki_factor = 1.0
        self.gravity_axial = np.full(1, GRAVITY_M_S2)
        self.tau_n = np.zeros(1)
        self.home_pose = (0.0, 0.0, float(self.home_strokes[0]))
        self.check = TestbenchCheck(cfg.waypoints, cfg.limits.stroke_margin_m, cfg.actuator.moving_mass_kg,
                                    cfg.actuator.stroke_m, leg_capacity(cfg))
        self.computed_torque = LegComputedTorque(cfg, 1, period_s)
        # its slide holds no static load: without the residuals a tight motion window stands in
        # for them; with them on the supervisor's backstop (at 20 bar it creeps out of a stick at 5 %)
        tight = not cfg.residuals.enabled
        self.plausibility_window = ((cfg.testbench.plausibility_spool, cfg.testbench.plausibility_cycles) if tight
                                    else (cfg.plausibility.spool, cfg.plausibility.cycles))
        ident = cfg.identification
        self.excitation = IdentificationSignal(ident.force_gain_v_n, ident.force_filter_hz, ident.stroke_guard_m,
                                               cfg.actuator.stroke_m, cfg.pi.saturation_v, period_s)

    def estimate(self, meas) -> Fault:
        """Nothing to estimate beyond the leg: its stroke is the measurement."""
        return Fault.NONE

    def pose_error_exceeds(self, joint_error_m) -> bool:
        """No platform: the leg's own tracking limit is the bound."""
        return False

    def update_payload(self, meas, accel_ref, healthy: bool) -> None:
        """No platform: the leg's load is the adaptive controller's RLS (eq. 7.33-7.37)."""

    payload = None
    payload_com_m = None
    payload_mass_kg = float("nan")

    def initialise(self, position_m) -> None:
        """Nothing but the leg's own estimators, which the controller starts."""

    def reference_forces(self, reference) -> bool:
        """No platform: no virtual-work forces along the reference."""
        return True

    def reset(self) -> None:
        """After a RESET: nothing of its own to forget."""

    def warm_up(self, reference) -> None:
        """No kernels of its own."""

    def forget(self) -> None:
        """Nothing computed at warm-up to forget."""


class HexapodModel:
    """The 6-UPS: its geometry with the declared payload, the pose by direct kinematics, the
    virtual-work forces along the reference, and the checks that need the pose."""

    name = "hexapod"
    n = 6
    n_nodes = 7                  # six leg nodes and the IMU
    excitation = None            # the identification tests are the test bench's

    def __init__(self, cfg: ControllerConfig, period_s: float, geometry: Geometry | None = None):
        from firmware_py.mechanics.platform import PlatformModel
        kinematics = cfg.kinematics
        bare = geometry or default_geometry()
        self.geometry = bare.with_payload(cfg.hexapod.payload_kg)
        self.platform = PlatformModel(self.geometry, kinematics.dk_tolerance_m, kinematics.dk_max_iterations,
                                      period_s)
        self.stroke_m = self.geometry.stroke_m
        self.home_strokes = self.platform.lengths - self.geometry.leg_min_m          # lengths at home
        self.park_strokes = np.full(6, cfg.hexapod.park_stroke_m)
        self.moving_mass_kg, self.mass_offset_kg = self.geometry.rod.mass_kg, 0.0
        self.rod_mass_kg = self.geometry.rod.mass_kg
        self.guide_friction = (0.0, 0.0)                      # the load cells hold the platform's joints
        self.kp_factor, self.ki_factor = cfg.hexapod.kp_factor, cfg.hexapod.ki_factor
        self.gravity_axial = self.platform.gravity_axial
        self.tau_n = self.platform.force_n
        self.home_pose = tuple(self.geometry.home_position_m)
        capacity = leg_capacity(cfg)
        self.check = HexapodCheck(cfg.waypoints, kinematics.dk_tolerance_m, self.geometry, capacity)
        ct = cfg.computed_torque
        self.yaw = YawFusion(period_s, ct.yaw_blend_s, ct.imu_max_age_s)
        self.computed_torque = ComputedTorque(cfg, self.geometry, period_s, self.yaw, capacity)
        self.plausibility_window = (cfg.plausibility.spool, cfg.plausibility.cycles)
        self.stop_cycles = round(cfg.supervisor.controlled_stop_s / period_s)
        self.attitude_check = AttitudeCrossCheck(cfg.plausibility.attitude_mismatch_rad,
                                                 cfg.plausibility.attitude_mismatch_samples)
        self.platform_error_max_m = cfg.limits.platform_error_max_m
        self.platform_angle_max_rad = cfg.limits.platform_angle_max_rad
        self.pose_error = np.zeros(6)              # Jx^-1 of the legs' errors: the platform's, first order
        self._ref_quat = self.platform.ref_dk.pose[3:7]
        self._lu = np.empty((6, 6))
        # the payload from the load cells, into every inverse dynamics the controller runs
        self.payload = (PayloadEstimator(bare, cfg.payload, cfg.hexapod.payload_kg, bare.platform.com_m)
                        if cfg.payload.estimate else None)
        self.payload_gate = cfg.payload.accel_gate_m_s2
        self.payload_com_m = np.full(3, np.nan)    # its centre of mass (platform frame), NaN: not placed
        self._pose_position, self._pose_quat = self.platform.dk.pose[0:3], self.platform.dk.pose[3:7]
        self._still, self._still6 = np.zeros(3), np.zeros(6)
        self._payload_dynamics = (self.platform.dynamics, self.computed_torque.dynamics, self.check.loads.dynamics)
        self.singularity_ratio_min = kinematics.singularity_ratio_min
        self.dk_failures_fault = kinematics.dk_failures_fault
        self.dk_failures = 0                 # direct kinematics not converged, cycles in a row

    @property
    def jacobian_scaled(self) -> np.ndarray:
        return self.platform.jacobian_scaled

    def estimate(self, meas) -> Fault:
        """Pose by direct kinematics, gravity along the legs, the yaw with the IMU's; the
        singularity and the IMU against the encoders (its sample against the DK of the same SYNC: every leg's frame
        of this cycle). The first fault found, or NONE."""
        platform = self.platform
        if not platform.estimate(meas.position_m):
            self.dk_failures += 1
            return Fault.DK_FAILURE if self.dk_failures >= self.dk_failures_fault else Fault.NONE
        self.dk_failures = 0
        self.yaw.update(quat_yaw(platform.dk.pose[3:7]), meas.attitude_rad, meas.attitude_fresh, meas.rate_rad_s,
                        meas.rate_fresh)
        if platform.det_ratio < self.singularity_ratio_min:
            return Fault.SINGULARITY
        if meas.attitude_fresh and all_set(meas.fresh) and self.attitude_check.update(platform.rot,
                                                                                      *meas.attitude_rad):
            return Fault.ATTITUDE_MISMATCH
        return Fault.NONE

    def update_payload(self, meas, accel_ref, healthy: bool) -> None:
        """A load-cell sample of the payload while nothing has latched and the legs' reference
        barely accelerates (the platform's pose from this cycle's estimate), into the inverse
        dynamics."""
        estimator = self.payload
        if (estimator is None or not healthy or not self.platform.converged or not all_set(meas.fresh)
                or any_beyond(accel_ref, self.payload_gate)):
            return
        platform = self.platform
        if estimator.update(self._pose_position, self._pose_quat, platform.rot, platform.jacobian,
                            platform.gravity_axial, meas.force_n, self._still):
            for dynamics in self._payload_dynamics:
                estimator.apply_to(dynamics)
            if not estimator.com_into(self.payload_com_m):
                self.payload_com_m.fill(np.nan)

    @property
    def payload_mass_kg(self) -> float:
        return self.payload.mass_kg if self.payload is not None else float("nan")

    def pose_error_exceeds(self, joint_error_m) -> bool:
        """The platform's pose error, from the legs' by the Jacobian at the measured pose (its
        yaw the fused one's while the IMU's is valid: the legs see 1 deg as about one encoder
        count; its IMU sample, not the estimate the held rate carries on), beyond [limits]
        platform_error_max_mm or platform_angle_max_deg."""
        if gauss_solve_into(self.platform.jacobian, joint_error_m, self._lu, self.pose_error, False) == 0.0:
            return False                     # singular: the singularity check's
        if self.yaw.valid:                   # the IMU's sample: past a turn the held rate overshoots
            self.pose_error[YAW] = wrapped(quat_yaw(self._ref_quat) - self.yaw.sampled_yaw_rad)
        return pose_beyond(self.pose_error, self.platform_error_max_m, self.platform_angle_max_rad)

    def initialise(self, position_m) -> None:
        """The pose and the reference's pose start at the measured strokes."""
        self.platform.estimate(position_m)
        self.platform.reset_reference(position_m)

    def reset(self) -> None:
        """After a RESET: the direct kinematics' failures are forgotten, and the payload starts
        again from the declared one (the fault's onset may have fed it a sensor's error)."""
        self.dk_failures = 0
        self.yaw.reset()
        if self.payload is not None:
            self.payload.reset()
            for dynamics in self._payload_dynamics:
                self.payload.apply_to(dynamics)
            self.payload_com_m.fill(np.nan)

    def reference_forces(self, reference) -> bool:
        """eq. 10.5's forces along the reference (model-based, computed torque); False: singular."""
        return self.platform.reference_forces(reference.yr, reference.vr)

    def warm_up(self, reference) -> None:
        """Load the platform's kernels now, then forget what they computed."""
        self.platform.estimate(self.home_strokes)
        self.platform.reset_reference(self.home_strokes)
        self.platform.reference_forces(self.home_strokes, reference.vr)
        any_beyond(reference.ar, self.payload_gate)
        self.yaw.warm_up()
        if self.payload is not None:                 # a sample of the bare platform at home
            platform, estimator = self.platform, self.payload
            estimator.bare.forces(self._pose_position, self._pose_quat, self._still6, self._still6)
            estimator.update(self._pose_position, self._pose_quat, platform.rot, platform.jacobian,
                             platform.gravity_axial, estimator.bare.force_n, self._still)
            estimator.apply_to(platform.dynamics)

    def forget(self) -> None:
        """The direct kinematics' warm start and the payload's warm-up sample are dropped."""
        self.platform.dk.reset()
        self.reset()


def rig_model(rig: str, cfg: ControllerConfig, period_s: float, geometry: Geometry | None = None):
    """The model of `rig` ("testbench" or "hexapod"); ValueError for another name."""
    if rig == "testbench":
        return TestbenchModel(cfg, period_s)
    if rig == "hexapod":
        return HexapodModel(cfg, period_s, geometry)
    raise ValueError(f"unknown rig {rig!r} (known: {', '.join(RIGS)})")
