"""The controller of one rig without the bus: `update()` is one cycle's update step
(supervision, reference, estimation, control, outputs) on arrays allocated here.

The loop (loop.py) fills the measurement arrays from the decoded frames (`meas_*`),
calls `update()`, and encodes `cw_*` and `spool` into VALVE_CMD frames. Host commands and
waypoints arrive through `host_command` and `waypoint_*` (events, outside the steady
cycle; they may allocate, the cycle does not).

Rigs: `testbench` (one leg; a waypoint's Z is the piston stroke) and `hexapod` (six legs;
waypoints are platform poses, joint references by inverse kinematics, pose estimate by
direct kinematics every cycle).
"""

from __future__ import annotations

import math

import numpy as np

from protocol.values import FLAG_LAST, FLAG_START, FLAG_STEP, TEST_ABORT

from .config import ControllerConfig
from .control import (
    IN_ACTIVE,
    IN_AR,
    IN_FORCE,
    IN_FRESH,
    IN_G_AX,
    IN_TAU,
    IN_VR,
    IN_Y,
    IN_YR,
    MODEL_BASED,
    ST_ERROR,
    ST_INTEGRAL,
    ST_MASS,
    ST_U,
    JointController,
)
from .geometry import GRAVITY_M_S2, Geometry, default_geometry
from .identification import TEST_MODES, IdentificationSignal, piston_force_n
from .plausibility import AttitudeCrossCheck, MotionPlausibility
from .supervisor import ACTIVE, Ack, Action, Command, Fault, State, Supervisor
from .trajectory import JointTrajectory, hold_at, sls_coefficients, through_points

RIGS = ("testbench", "hexapod")
VALVE_FAULT_STATES = (4, 5)            # CiA 408 FAULT_HOLD, FAULT_DISABLED
MOTION_COMMANDS = (Command.ENABLE, Command.HOME, Command.PARK, Command.START)
RESET_GRACE_CYCLES = 4                 # valves need a SYNC or two to leave FAULT after R
RECOVERY_INSET_M = 2e-3                # enabled inside the end-stop guard: held this far inside it
RECOVERY_CYCLES = 500                  # ... and back inside the guard within 1 s (500 Hz)
RECOVERY_SLACK_M = 0.5e-3              # ... never more than this further out (encoder steps, noise)


class ControllerCore:
    def __init__(self, cfg: ControllerConfig, rig: str, period_s: float, controller: int = 0,
                 geometry: Geometry | None = None):
        if rig not in RIGS:
            raise ValueError(f"unknown rig {rig!r} (known: {', '.join(RIGS)})")
        self.cfg, self.rig, self.period_s = cfg, rig, period_s
        self.hexapod = rig == "hexapod"
        self.n = 6 if self.hexapod else 1
        n = self.n
        if self.hexapod:
            from .platform import PlatformModel
            self.geometry = geometry or default_geometry()
            self.platform = PlatformModel(self.geometry, cfg.dk_tolerance_m, cfg.dk_max_iterations, period_s)
            self.stroke_m = self.geometry.stroke_m
            self.home_strokes = self.platform.lengths - self.geometry.leg_min_m     # lengths at home
            self.park_strokes = np.full(n, cfg.hexapod_park_stroke_m)
            moving_mass = self.geometry.rod.mass_kg
            mass_offset = 0.0
            kp_factor, ki_factor = cfg.hexapod_kp_factor, cfg.hexapod_ki_factor
        else:
            self.geometry = None
            self.platform = None
            self.stroke_m = cfg.stroke_m
            self.home_strokes = np.full(n, cfg.testbench_home_m)
            self.park_strokes = np.full(n, cfg.testbench_park_m)
            moving_mass = cfg.moving_mass_kg
            mass_offset = cfg.slide_mass_kg
            kp_factor, ki_factor = 1.0, 1.0
        self.joint = JointController(cfg, n, period_s, moving_mass_kg=moving_mass, mass_offset_kg=mass_offset,
                                     kp_factor=kp_factor, ki_factor=ki_factor)
        self.sup = Supervisor(controller)
        self.joint.set_mode(controller)
        # measurements (filled by the loop each cycle)
        self.meas_y = np.zeros(n)
        self.meas_force = np.zeros(n)
        self.meas_fresh = np.zeros(n, dtype=bool)
        self.meas_attitude = np.zeros(3)       # IMU roll, pitch, yaw [rad] (hexapod)
        self.attitude_fresh = False            # a new IMU_ATTITUDE arrived this cycle
        self.meas_bad = np.zeros(n, dtype=bool)          # an E2E-rejected frame of the leg this cycle
        self.meas_sensor_fault = np.zeros(n, dtype=bool)
        self.valve_state = np.zeros(n, dtype=np.int64)
        self.meas_pa = np.zeros(n)             # chamber pressures [Pa], every 16th SYNC (LEG_PRESSURE)
        self.meas_pb = np.zeros(n)
        self.pressure_seen = np.zeros(n, dtype=bool)
        # identification tests (HOST_TEST, test bench only: chapter 6.4)
        self.test = None if self.hexapod else IdentificationSignal(
            cfg.test_force_gain_v_n, cfg.test_stroke_guard_m, cfg.stroke_m, cfg.saturation_v, period_s)
        # outputs
        self.cw_d = np.ones(n)
        self.cw_h = np.ones(n)
        self.cw_m = np.zeros(n)
        self.cw_r = np.zeros(n)
        self.spool = np.zeros(n)                          # fraction of full valve input
        # reference
        self.yr = np.zeros(n)
        self.vr = np.zeros(n)
        self.ar = np.zeros(n)
        self.hold_position = np.zeros(n)
        # enabled with a leg inside the end-stop guard (after a POSITION_LIMIT fault): it is
        # held just inside the guard and may come back, but never go further out
        self.recovering = np.zeros(n, dtype=bool)
        self.recovery_from = np.zeros(n)
        self.recovery_cycles = 0
        self.trajectory: JointTrajectory | None = None
        self.trajectory_start_cycle = 0        # the trajectory's clock: t = (cycles - this) * period
        self.trajectory_seqs: list[int] = []
        self.trajectory_ends = np.full(cfg.waypoint_queue + 2, np.inf)     # end time of each segment
        self.trajectory_segments = 0
        self._segment = 0
        self.active_waypoint = 0
        # supervision
        self.missing = np.zeros(n, dtype=np.int64)
        self.bad = np.zeros(n, dtype=np.int64)
        self._mask = np.zeros(n, dtype=bool)
        self._mask3 = np.zeros((n, 3), dtype=bool)
        self._abs = np.zeros(n)
        spool, cycles = ((cfg.plausibility_spool, cfg.plausibility_cycles) if self.hexapod else
                         (cfg.testbench_plausibility_spool, cfg.testbench_plausibility_cycles))
        self.plausibility = MotionPlausibility(n, spool * cfg.valve_full_scale_v, cycles, cfg.plausibility_travel_m)
        self.attitude_check = AttitudeCrossCheck(cfg.attitude_mismatch_rad, cfg.attitude_mismatch_samples)
        self.overruns_in_row = 0
        self.dk_failures = 0
        self.reset_cycles = 0
        self._reset_pulse = False
        self.time_s = 0.0
        self.cycles = 0
        self.initialised = False
        self.reinitialise = False              # a RESET waits for a complete fresh set of measurements
        # waypoints
        self.queue: list[dict] = []
        self.expected_seq: int | None = None
        self._staged_pos: dict[int, tuple] = {}
        self._staged_rot: dict[int, tuple] = {}
        if self.hexapod:
            from .dynamics import InverseDynamics
            from .kinematics import DirectKinematics
            self._check_dk = DirectKinematics(self.geometry, cfg.dk_tolerance_m, 50)
            self._check_dynamics = InverseDynamics(self.geometry)
        self._warm_up()

    def _warm_up(self) -> None:
        """Load every compiled kernel now (configure), not in the first cycle."""
        self.joint.update()
        if self.hexapod:
            self.platform.estimate(self.home_strokes)
            self.platform.reset_reference(self.home_strokes)
            self.platform.reference_forces(self.home_strokes, self.vr)
            self.platform.dk.reset()
        self.joint.reset(0.0)

    # -- helpers ----------------------------------------------------------------------------
    @property
    def state(self) -> State:
        return self.sup.state

    def _start_hold(self, position) -> None:
        self.hold_position[:] = position
        self.trajectory = None

    def _inside_guard(self, position: np.ndarray) -> np.ndarray:
        """`position` moved RECOVERY_INSET inside the end-stop guard where it is not; those legs
        are marked recovering (the POSITION_LIMIT check lets them come back for a while)."""
        low = self.cfg.stroke_margin_m + RECOVERY_INSET_M
        high = self.stroke_m - low
        target = np.clip(position, low, high)
        np.not_equal(target, position, out=self.recovering)
        self.recovery_from[:] = position
        self.recovery_cycles = RECOVERY_CYCLES if self.recovering.any() else 0
        return target

    def _move(self, target, speed_m_s: float, accel_time_s: float) -> None:
        """Point-to-point SLS from the current reference to `target` (joint space)."""
        start = self.yr.copy() if self.initialised else self.meas_y.copy()
        distance = float(np.max(np.abs(np.asarray(target) - start)))
        duration = max(distance / speed_m_s + accel_time_s, 2.0 * accel_time_s)
        self.play(through_points(np.array([start, target]), accel_time_s, duration), [self.active_waypoint])

    def play(self, trajectory: JointTrajectory, seqs: list[int]) -> None:
        """Follow `trajectory` (joint strokes) from now; `seqs` name its segments in CTRL_STATUS."""
        self.trajectory = trajectory
        self.trajectory_start_cycle = self.cycles
        self.trajectory_seqs = seqs
        seg = trajectory.segments[:, 0]
        n = len(seg)
        if n > len(self.trajectory_ends):
            self.trajectory_ends = np.full(n, np.inf)
        np.add(seg[:, 4], seg[:, 6], out=self.trajectory_ends[:n])     # T_START + TM
        self.trajectory_ends[n:] = np.inf
        self.trajectory_segments = n
        self._segment = 0

    # -- host interface (events) ------------------------------------------------------------
    def host_command(self, command: int, argument: int) -> Ack:
        if self.reinitialise and command in MOTION_COMMANDS:
            return Ack.BAD_STATE             # after RESET: not before every sensor has reported again
        result = self.sup.command(command, argument)
        if result is Ack.ACCEPTED:
            self._do_action()
        return result

    def piston_force(self) -> float:
        """Leg 1's F_p from its latest chamber pressures (eq. 6.5)."""
        return piston_force_n(self.meas_pa[0], self.meas_pb[0], self.cfg.piston_area_m2, self.cfg.area_ratio)

    def test_command(self, mode: int, valve_v: float, force_n: float, duration_s: float) -> Ack:
        """HOST_TEST (test bench): start an identification test from READY, or ABORT the one
        running (the leg then holds where it is)."""
        test = self.test
        if test is None or mode not in TEST_MODES or not all(map(math.isfinite, (valve_v, force_n, duration_s))):
            return Ack.BAD_ARGUMENT
        if mode == TEST_ABORT:
            if not test.running:
                return Ack.BAD_STATE
            self._end_test()
            return Ack.ACCEPTED
        if duration_s <= 0.0 or abs(valve_v) > self.cfg.saturation_v:
            return Ack.BAD_ARGUMENT
        if (self.sup.state is not State.READY or self.trajectory is not None or self.reinitialise
                or not self.pressure_seen[0]):
            return Ack.BAD_STATE
        test.start(mode, valve_v, force_n, duration_s, self.cycles, self.piston_force(),
                   float(self.joint.st[0, ST_U]))           # the holding input: FORCE_SINE starts bumpless
        self.sup.start_running()
        return Ack.ACCEPTED

    def _end_test(self) -> None:
        self.test.stop()
        self.hold_position[:] = self.joint.kalman_x[:, 0]
        self.sup.motion_done()

    def _do_action(self) -> None:
        action, self.sup.action = self.sup.action, Action.NONE
        cfg = self.cfg
        if self.test is not None and self.test.running and action is not Action.NONE:
            self.test.stop()                 # STOP (or anything else that moves the leg) ends a test
        if action is Action.ENABLE:
            self._start_hold(self._inside_guard(self.meas_y))
            self.joint.st[:, ST_INTEGRAL] = 0.0
        elif action in (Action.HOME, Action.PARK):
            target = self.park_strokes if action is Action.PARK else self.home_strokes
            if not self.initialised:
                self.yr[:] = self.meas_y
            self._move(target, cfg.homing_speed_m_s, cfg.homing_accel_time_s)
        elif action is Action.START:
            self._start_queue()
        elif action is Action.STOP:
            ta = cfg.homing_accel_time_s
            coeffs = sls_coefficients(self.yr, self.vr, self.yr + self.vr * ta, ta, 2.0 * ta, True)
            self.play(JointTrajectory(coeffs[None]), [self.active_waypoint])
        elif action is Action.RESET:
            self.reset_cycles = RESET_GRACE_CYCLES
            self.missing[:] = 0
            self.bad[:] = 0
            self.overruns_in_row = 0
            self.dk_failures = 0
            self.trajectory = None
            # estimators and reference start again at the first complete set of fresh
            # measurements after it: after an outage the Kalman filter had predicted on for
            # seconds, and holding where the legs were last seen (not where a restarted sensor
            # node now reads them) drove them there (VELOCITY_LIMIT at the ENABLE after it)
            self.reinitialise = True
        elif action is Action.CLEAR:
            self.queue.clear()
            self.expected_seq = None

    def _start_queue(self) -> None:
        if not self.queue:
            return
        take = next((k + 1 for k, w in enumerate(self.queue) if w["flags"] & FLAG_LAST), len(self.queue))
        chosen, self.queue = self.queue[:take], self.queue[take:]
        if chosen[0]["flags"] & FLAG_STEP:                # a step reference (chapters 5.4, 7.6.1)
            self.play(hold_at(chosen[0]["strokes"], chosen[0]["segment_time"]), [chosen[0]["seq"]])
        else:
            points = np.array([self.yr] + [w["strokes"] for w in chosen])
            self.play(through_points(points, [w["accel_time"] for w in chosen],
                                     [w["segment_time"] for w in chosen]), [w["seq"] for w in chosen])
        self.sup.start_running()

    def waypoint_position(self, tag: int, x: float, y: float, z: float) -> None:
        self._staged_pos[tag & 0x0F] = (x, y, z)

    def waypoint_rotation(self, tag: int, roll: float, pitch: float, yaw: float) -> None:
        self._staged_rot[tag & 0x0F] = (roll, pitch, yaw)

    def queue_free(self) -> int:
        return max(self.cfg.waypoint_queue - len(self.queue), 0)

    def waypoint_time(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int) -> Ack:
        """Commit the staged pose with this TAG: check it and queue it, or reject it."""
        tag &= 0x0F
        pos = self._staged_pos.pop(tag, None)
        rot = self._staged_rot.pop(tag, None)
        if pos is None or rot is None or (seq & 0x0F) != tag:
            return Ack.INCOMPLETE
        if self.expected_seq is not None and seq != self.expected_seq:
            return Ack.SEQUENCE_GAP
        if self.state not in (State.IDLE, State.READY, State.RUNNING):
            return Ack.BAD_STATE
        if len(self.queue) >= self.cfg.waypoint_queue:
            return Ack.QUEUE_FULL
        values = pos + rot + (segment_time, accel_time)
        if not all(math.isfinite(v) for v in values):
            return Ack.NOT_FINITE
        if not (accel_time > 0.0 and segment_time >= 2.0 * accel_time):
            return Ack.BAD_ARGUMENT
        step = bool(flags & FLAG_STEP)
        if step and (not flags & FLAG_LAST or (self.queue and not self.queue[-1]["flags"] & FLAG_LAST)):
            return Ack.BAD_ARGUMENT                         # a step is a trajectory of its own
        previous = self.queue[-1]["strokes"] if self.queue else (
            self.trajectory_target() if self.trajectory is not None else self.yr.copy())
        result, strokes = (self._check_hexapod(previous, pos, rot, segment_time, accel_time, step) if self.hexapod
                           else self._check_testbench(previous, pos, rot, segment_time, accel_time, step))
        if result is not Ack.ACCEPTED:
            return result
        self.queue.append({"seq": seq, "strokes": strokes, "segment_time": segment_time,
                           "accel_time": accel_time, "flags": flags, "pose": pos + rot})
        self.expected_seq = (seq + 1) % 256
        if flags & FLAG_START and self.state is State.READY:
            self.host_command(Command.START, 0)
        return Ack.ACCEPTED

    def trajectory_target(self) -> np.ndarray:
        out = np.empty(self.n)
        self.trajectory.evaluate_into(1e9, out, np.empty(self.n), np.empty(self.n))
        return out

    def _peak_velocity_ok(self, previous, strokes, segment_time, accel_time, step: bool) -> bool:
        """A step is bounded by its size; a segment by its peak joint velocity."""
        distance = float(np.max(np.abs(strokes - previous)))
        if step:
            return distance <= self.cfg.waypoint_step_max_m
        return distance / (segment_time - accel_time) <= self.cfg.waypoint_velocity_max_m_s

    def _check_testbench(self, previous, pos, rot, segment_time, accel_time, step):
        margin = self.cfg.stroke_margin_m
        if max(abs(pos[0]), abs(pos[1]), *(abs(r) for r in rot)) > 1e-9 or not (
                margin <= pos[2] <= self.stroke_m - margin):
            return Ack.OUTSIDE_WORKSPACE, None
        strokes = np.array([pos[2]])
        if not self._peak_velocity_ok(previous, strokes, segment_time, accel_time, step):
            return Ack.TOO_FAST, None
        if step:
            return Ack.ACCEPTED, strokes
        # the static load as estimated plus the segment's peak SLS acceleration
        peak_accel = abs(pos[2] - float(previous[0])) / (segment_time - accel_time) * math.pi / (2.0 * accel_time)
        force = (self.cfg.moving_mass_kg + float(self.joint.st[0, ST_MASS])) * (GRAVITY_M_S2 + peak_accel)
        if force > self.cfg.waypoint_force_max_n:
            return Ack.TOO_FAST, None
        return Ack.ACCEPTED, strokes

    def _check_hexapod(self, previous, pos, rot, segment_time, accel_time, step):
        """Target and joint-space path in one workspace check (its cost is mostly per call)."""
        from .kinematics import ik_batch
        from .rotation import rpy_to_quat
        from .workspace import MIN_CONDITION_INDEX, check_poses

        g = self.geometry
        samples = self.cfg.waypoint_path_samples
        poses, quats = np.empty((samples + 1, 3)), np.empty((samples + 1, 4))
        poses[0], quats[0] = pos, rpy_to_quat(*rot)                 # row 0: the target itself
        lengths, _ = ik_batch(g, poses[:1], quats[:1])
        strokes = lengths[0] - g.leg_min_m
        # the joint-space path between the waypoints, pose by pose, back from the target
        n = 1
        self._check_dk.pose[:] = np.concatenate([poses[0], quats[0]])
        for s in np.linspace(1.0, 0.0, samples):
            self._check_dk.solve(g.leg_min_m + previous + s * (strokes - previous))
            if not self._check_dk.converged:
                break
            poses[n], quats[n] = self._check_dk.pose[0:3], self._check_dk.pose[3:7]
            n += 1
        report = check_poses(g, poses[:n], quats[:n])
        if not report.reachable[0]:
            return Ack.OUTSIDE_WORKSPACE, None
        if report.condition_index[0] < MIN_CONDITION_INDEX:
            return Ack.SINGULAR, None
        if not self._peak_velocity_ok(previous, strokes, segment_time, accel_time, step):
            return Ack.TOO_FAST, None
        if n < samples + 1 or not report.reachable.all():
            return Ack.OUTSIDE_WORKSPACE, None
        if np.min(report.condition_index) < MIN_CONDITION_INDEX:
            return Ack.SINGULAR, None
        # static load plus the peak SLS acceleration of the segment's translation
        peak_accel = (poses[0] - poses[n - 1]) / (segment_time - accel_time) * math.pi / (2.0 * accel_time)
        twist = np.zeros(6)
        accel = np.concatenate([peak_accel, np.zeros(3)])
        if not self._check_dynamics.forces(poses[0], quats[0], twist, accel):
            return Ack.SINGULAR, None
        if np.max(np.abs(self._check_dynamics.force_n)) > self.cfg.waypoint_force_max_n:
            return Ack.TOO_FAST, None
        return Ack.ACCEPTED, strokes

    # -- the cycle ---------------------------------------------------------------------------
    def initialise(self, keep_load: bool = False) -> None:
        """First measurements are in (or the first after a RESET): estimators and the reference
        start at the measured state; `keep_load` keeps the load's mass estimate."""
        gravity = GRAVITY_M_S2
        if self.hexapod:
            self.platform.estimate(self.meas_y)
            gravity = self.platform.gravity_axial
            self.platform.reset_reference(self.meas_y)
        if keep_load:
            self.joint.restart_at(self.meas_y, gravity)
        else:
            self.joint.reset(self.meas_y, gravity)
        self.yr[:] = self.meas_y
        self.hold_position[:] = self.meas_y
        self.initialised = True

    def fault(self, code: Fault) -> None:
        self.sup.fault(code)

    def activated(self, auto_enable: bool) -> None:
        """Activation is over (valves in HOLD): IDLE, or READY holding the measured position."""
        self.sup.booted(auto_enable)
        self._do_action()

    def update(self, overrun: bool = False) -> None:
        """One cycle: supervise the inputs, reference, estimation and control, outputs."""
        cfg, sup, joint = self.cfg, self.sup, self.joint
        inputs = joint.inputs
        self.cycles += 1
        self.time_s += self.period_s
        self._reset_pulse = self.reset_cycles == RESET_GRACE_CYCLES      # R high for one cycle
        if not self.initialised:
            if self.meas_fresh.all():
                self.initialise()
            else:
                self._write_outputs()
                return
        elif self.reinitialise and self.meas_fresh.all():
            self.initialise(keep_load=True)
            self.reinitialise = False
        # sensor frames: missing and E2E-rejected, consecutive
        np.logical_not(self.meas_fresh, out=self._mask)
        np.multiply(self.missing, self._mask, out=self.missing)
        np.add(self.missing, self._mask, out=self.missing)
        np.logical_and(self.meas_bad, self._mask, out=self._mask)
        np.multiply(self.bad, self._mask, out=self.bad)
        np.add(self.bad, self._mask, out=self.bad)
        if self.bad.max() >= cfg.e2e_errors_fault:
            sup.fault(Fault.E2E_ERROR)
        if self.missing.max() >= cfg.missing_frames_fault:
            sup.fault(Fault.SENSOR_TIMEOUT)
        if self.meas_sensor_fault.any():
            sup.fault(Fault.SENSOR_FAULT)
        self.overruns_in_row = self.overruns_in_row + 1 if overrun else 0
        if self.overruns_in_row >= cfg.overruns_fault:
            sup.fault(Fault.OVERRUN)
        if self.reset_cycles > 0:
            self.reset_cycles -= 1
        elif sup.state not in (State.FAULT, State.ESTOP, State.BOOT):
            for state in VALVE_FAULT_STATES:
                np.equal(self.valve_state, state, out=self._mask)
                if self._mask.any():
                    sup.fault(Fault.VALVE_FAULT)
        # platform: pose estimate and gravity along the legs
        if self.hexapod:
            if self.platform.estimate(self.meas_y):
                self.dk_failures = 0
                if self.platform.det_ratio < cfg.singularity_ratio_min:
                    sup.fault(Fault.SINGULARITY)
                if self.attitude_fresh and self.attitude_check.update(
                        self.platform.rot, self.meas_attitude[0], self.meas_attitude[1], self.meas_attitude[2]):
                    sup.fault(Fault.ATTITUDE_MISMATCH)
            else:
                self.dk_failures += 1
                if self.dk_failures >= cfg.dk_failures_fault:
                    sup.fault(Fault.DK_FAILURE)
            inputs[:, IN_G_AX] = self.platform.gravity_axial
            self.attitude_fresh = False
        else:
            inputs[:, IN_G_AX] = GRAVITY_M_S2
        # reference
        active = sup.state in ACTIVE
        testing = self.test is not None and self.test.running
        if testing and not active:
            self.test.stop()                         # a fault or an e-stop ends it: valves hold
            testing = False
        if testing:                                  # the test drives the valve: the loop follows the leg
            self.yr[:] = joint.kalman_x[:, 0]
            self.vr[:] = 0.0
            self.ar[:] = 0.0
        elif active and self.trajectory is not None:
            # integer cycles, not an accumulated float: a log's analysis rebuilds the same reference
            t = (self.cycles - self.trajectory_start_cycle) * self.period_s
            self.trajectory.evaluate_into(t, self.yr, self.vr, self.ar)
            while self._segment < self.trajectory_segments - 1 and t >= self.trajectory_ends[self._segment]:
                self._segment += 1
            if self._segment < len(self.trajectory_seqs):
                self.active_waypoint = self.trajectory_seqs[self._segment]
            if t >= self.trajectory_ends[self.trajectory_segments - 1]:
                self.hold_position[:] = self.yr
                self.trajectory = None
                sup.motion_done()
                if self.queue and self.queue[0]["flags"] & FLAG_START and sup.state is State.READY:
                    self._start_queue()               # queued "start now": as soon as the last one ends
        elif active:
            self.yr[:] = self.hold_position
            self.vr[:] = 0.0
            self.ar[:] = 0.0
        else:                                     # valves locked: follow the measurement
            self.yr[:] = joint.kalman_x[:, 0]
            self.vr[:] = 0.0
            self.ar[:] = 0.0
            self.hold_position[:] = self.yr
        if self.hexapod and sup.controller == MODEL_BASED:
            if not self.platform.reference_forces(self.yr, self.vr) and active:
                sup.fault(Fault.SINGULARITY)
            inputs[:, IN_TAU] = self.platform.force_n
        # estimation and control
        inputs[:, IN_Y] = self.meas_y
        inputs[:, IN_FRESH] = self.meas_fresh
        inputs[:, IN_FORCE] = self.meas_force
        inputs[:, IN_YR] = self.yr
        inputs[:, IN_VR] = self.vr
        inputs[:, IN_AR] = self.ar
        inputs[:, IN_ACTIVE] = 1.0 if sup.state in ACTIVE else 0.0
        if joint.mode != sup.controller:
            joint.set_mode(sup.controller)
        joint.update()
        if testing:
            u, done = self.test.output(self.cycles, self.meas_y[0], self.piston_force())
            joint.st[0, ST_U] = u
            if done:
                self._end_test()
        self._limits(active)
        self._write_outputs()

    def _position_limit(self, margin: float) -> None:
        """A leg inside the end-stop guard faults, unless it is coming back from where it was
        enabled (within RECOVERY_CYCLES and never further out)."""
        for leg in range(self.n):
            y = self.meas_y[leg]
            if margin <= y <= self.stroke_m - margin:
                self.recovering[leg] = False
                continue
            edge = margin if y < margin else self.stroke_m - margin
            coming_back = (self.recovering[leg] and self.recovery_cycles > 0
                           and abs(y - edge) <= abs(self.recovery_from[leg] - edge) + RECOVERY_SLACK_M)
            if not coming_back:
                self.sup.fault(Fault.POSITION_LIMIT)
                return

    def _limits(self, active: bool) -> None:
        cfg, sup, joint = self.cfg, self.sup, self.joint
        u = joint.st[:, ST_U]
        np.isfinite(u, out=self._mask)
        finite = self._mask.all()
        np.isfinite(joint.kalman_x, out=self._mask3)
        if not (finite and self._mask3.all()):
            sup.fault(Fault.NOT_FINITE)
        np.abs(self.meas_force, out=self._abs)
        if self._abs.max() > cfg.force_max_n:
            sup.fault(Fault.FORCE_LIMIT)
        if not active:
            self.plausibility.reset()
            return
        margin = cfg.stroke_margin_m
        if self.recovery_cycles > 0:
            self.recovery_cycles -= 1
        if self.meas_y.min() < margin or self.meas_y.max() > self.stroke_m - margin:
            self._position_limit(margin)
        elif self.recovery_cycles > 0:
            self.recovering[:] = False
            self.recovery_cycles = 0
        np.abs(joint.kalman_x[:, 1], out=self._abs)
        if self._abs.max() > cfg.velocity_max_m_s:
            sup.fault(Fault.VELOCITY_LIMIT)
        np.abs(joint.st[:, ST_ERROR], out=self._abs)
        if self._abs.max() > cfg.tracking_error_max_m:
            sup.fault(Fault.TRACKING_ERROR)
        if self.plausibility.update(u, self.meas_y):
            sup.fault(Fault.MOTION_PLAUSIBILITY)

    def _write_outputs(self) -> None:
        """Control words and spool setpoints for the state the supervisor is in now."""
        state = self.sup.state
        self.cw_r[:] = 1.0 if self._reset_pulse else 0.0
        if state is State.ESTOP:
            self.cw_d[:] = 0.0
            self.cw_h[:] = 0.0
            self.cw_m[:] = 0.0
            self.spool[:] = 0.0
            return
        self.cw_d[:] = 1.0
        self.cw_h[:] = 1.0
        if state in ACTIVE:
            self.cw_m[:] = 1.0
            np.multiply(self.joint.st[:, ST_U], 1.0 / self.cfg.valve_full_scale_v, out=self.spool)
            np.isfinite(self.spool, out=self._mask)
            if not self._mask.all():
                self.spool[:] = 0.0
                self.cw_m[:] = 0.0
        else:
            self.cw_m[:] = 0.0
            self.spool[:] = 0.0

    def force_outputs(self, hold: bool) -> None:
        """Shutdown: every valve to HOLD (hold=True) or DISABLED, whatever the state."""
        self.cw_r[:] = 0.0
        self.cw_d[:] = 1.0 if hold else 0.0
        self.cw_h[:] = 1.0 if hold else 0.0
        self.cw_m[:] = 0.0
        self.spool[:] = 0.0
