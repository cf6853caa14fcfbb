"""The controller of one rig without the bus: `update(meas, cmd)` is one cycle (supervision,
the host's frames, reference, estimation, control, limits, valve commands) on arrays made
here; it allocates nothing in the steady cycle.

Rigs: `testbench` (one leg; a waypoint's Z is the piston stroke) and `hexapod` (six legs;
waypoints are platform poses, joint references by inverse kinematics, the pose estimated by
direct kinematics every cycle). Host frames reach it through `host` (hostlink.py); the
methods they end in (`host_command`, `waypoint_commit`, `test_command`) are events and may
allocate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.config import ControllerConfig
from firmware_py.hostlink import HostLink
from firmware_py.mechanics.geometry import Geometry, default_geometry
from firmware_py.motion_control.computed_torque import ComputedTorque, LegComputedTorque
from firmware_py.motion_control.excitation import TEST_MODES, IdentificationSignal
from firmware_py.motion_control.joint_space import COMPUTED_TORQUE, MODEL_BASED, JointController
from firmware_py.motion_control.reference import Reference
from firmware_py.motion_control.trajectory import through_points
from firmware_py.supervision.monitors import FrameMonitor, LimitMonitor, LoopMonitor, NodeMonitor
from firmware_py.supervision.plausibility import AttitudeCrossCheck, FrozenLoadCells, MotionPlausibility, SupplyPressure
from firmware_py.supervision.residuals import ActuatorResiduals, ChamberPrediction, SpoolResidual, sample_floor_pa
from firmware_py.supervision.stopping import ControlledStop
from firmware_py.supervision.supervisor import ACTIVE, LATCHED, Action, Supervisor
from firmware_py.supervision.waypoints import HexapodCheck, TestbenchCheck, WaypointQueue
from physics import hydraulics as hy
from physics.actuator import piston_force
from physics.constants import BAR, GRAVITY_M_S2
from protocol.dbc import signal_scale
from protocol.enums import Ack, Command, Fault, State, TestMode, ValveState, WaypointFlag
from protocol.interfaces import Measurements, ValveCommands

RIGS = ("testbench", "hexapod")
MOTION_COMMANDS = (Command.ENABLE, Command.HOME, Command.PARK, Command.START)
PEAK_DELAY = 64                        # cycles: a fault's residual rises over fewer than this before it latches
RESET_GRACE_CYCLES = 4                 # valves need a SYNC or two to leave FAULT after R


class Controller:
    def __init__(self, cfg: ControllerConfig, rig: str, period_s: float, controller: int = 0,
                 geometry: Geometry | None = None):
        if rig not in RIGS:
            raise ValueError(f"unknown rig {rig!r} (known: {', '.join(RIGS)})")
        self.cfg, self.rig, self.period_s = cfg, rig, period_s
        self.hexapod = rig == "hexapod"
        self.n = n = 6 if self.hexapod else 1
        if self.hexapod:
            from firmware_py.mechanics.platform import PlatformModel
            self.geometry = (geometry or default_geometry()).with_payload(cfg.hexapod.payload_kg)
            kin = cfg.kinematics
            self.platform = PlatformModel(self.geometry, kin.dk_tolerance_m, kin.dk_max_iterations, period_s)
            self.stroke_m = self.geometry.stroke_m
            self.home_strokes = self.platform.lengths - self.geometry.leg_min_m     # lengths at home
            self.park_strokes = np.full(n, cfg.hexapod.park_stroke_m)
            moving_mass, mass_offset = self.geometry.rod.mass_kg, 0.0
            kp_factor, ki_factor = cfg.hexapod.kp_factor, cfg.hexapod.ki_factor
            check = HexapodCheck(cfg.waypoints, cfg.kinematics.dk_tolerance_m, self.geometry)
            self.gravity_axial = self.platform.gravity_axial
            self.tau_n = self.platform.force_n
            self.computed_torque = ComputedTorque(cfg, self.geometry, period_s)
        else:
            self.geometry = None
            self.platform = None
            self.stroke_m = cfg.actuator.stroke_m
            self.home_strokes = np.full(n, cfg.testbench.home_m)
            self.park_strokes = np.full(n, cfg.testbench.park_m)
            moving_mass, mass_offset = cfg.actuator.moving_mass_kg, cfg.testbench.slide_mass_kg
            kp_factor, ki_factor = 1.0, 1.0
            check = TestbenchCheck(cfg.waypoints, cfg.limits.stroke_margin_m, cfg.actuator.moving_mass_kg,
                                   cfg.actuator.stroke_m)
            self.gravity_axial = np.full(n, GRAVITY_M_S2)
            self.tau_n = np.zeros(n)
            self.computed_torque = LegComputedTorque(cfg, n, period_s)
        self.joint = JointController(cfg, n, period_s, moving_mass_kg=moving_mass, mass_offset_kg=mass_offset,
                                     kp_factor=kp_factor, ki_factor=ki_factor)
        self.sup = Supervisor(controller)
        self.joint.set_mode(controller)
        self.reference = Reference(n, period_s, cfg.waypoints.queue + 2)
        self.waypoints = WaypointQueue(cfg.waypoints, check)
        self.host = HostLink()
        # supervision
        self.loop_monitor = LoopMonitor(cfg.supervisor)
        self.node_monitor = NodeMonitor(cfg.timing.heartbeat_timeout_s)
        self.frames = FrameMonitor(cfg.supervisor, n)
        self.limits = LimitMonitor(cfg.limits, n, self.stroke_m)
        # the test bench's tight window stands in for the residuals when they are off; with them
        # on it is the supervisor's backstop (at 20 bar the slide creeps out of a stick at 5 %)
        tight = not self.hexapod and not cfg.residuals.enabled
        spool, cycles = ((cfg.testbench.plausibility_spool, cfg.testbench.plausibility_cycles) if tight else
                         (cfg.plausibility.spool, cfg.plausibility.cycles))
        plausible = cfg.plausibility
        self.plausibility = MotionPlausibility(n, spool * cfg.actuator.valve_full_scale_v, cycles, plausible.travel_m)
        self.attitude_check = AttitudeCrossCheck(plausible.attitude_mismatch_rad, plausible.attitude_mismatch_samples)
        res, encoder_m = cfg.residuals, cfg.actuator.encoder_resolution_m
        supply_pa = cfg.hydraulic_model.supply_pressure_pa
        self.load_cells = FrozenLoadCells(n, res.load_cell_noise_n, signal_scale("LEG_STATE_1", "FORCE"))
        # each actuator's chamber model against its load cell, while the valves are ACTIVE; the
        # cylinder's own stroke sets its chamber volumes
        self.residuals = ActuatorResiduals(
            n, cfg.hydraulics, cfg.friction.vector, supply_pa, period_s,
            self.geometry.rod.mass_kg if self.hexapod else cfg.actuator.moving_mass_kg, res.column_stiffness_n_m,
            encoder_m, res.correction_gain, res.filter_s, res.persistence_cycles, res.flow_spread)
        self.spool_check = SpoolResidual(n, cfg.hydraulics, period_s, res.spool_floor, res.spool_lag_spread,
                                         res.spool_persistence_cycles, int(ValveState.ACTIVE))
        # each leg's chambers from one LEG_PRESSURE sample to the next
        floor_pa = sample_floor_pa(res.pressure_noise_pa, signal_scale("LEG_PRESSURE_1", "PA") * BAR)
        self.chambers = ChamberPrediction(n, cfg.hydraulics, supply_pa, period_s, encoder_m, res.flow_spread,
                                          res.leakage_spread, res.stiffness_spread, floor_pa,
                                          res.pressure_persistence_samples, int(ValveState.ACTIVE))
        self.residuals_running = False
        # the valves' P-port transducers against the supply the model assumes
        self.supply = SupplyPressure(n, supply_pa, cfg.hydraulics[hy.HP_TANK], res.flow_spread, res.supply_legs)
        # spool setpoints sent: the last cycle's (applied at this SYNC), the one before (applied
        # over the period this cycle's measurements close) and the one before that (applied
        # then when the other came late)
        self.spool_sent = np.zeros(n)
        self.spool_applied = np.zeros(n)
        self.spool_late = np.zeros(n)
        # the false-alarm margin's measure: the largest |r| / threshold before the first fault,
        # less the PEAK_DELAY cycles before it (a fault's own rise)
        self.residual_peak = 0.0
        self.supply_peak = 0.0                   # the same for the supply's samples
        self.spool_peak = 0.0                    # ... for the valves' spools
        self.pressure_peak = 0.0                 # ... for the chambers' samples
        self.attitude_peak = 0.0                 # ... and for the IMU against the encoders
        self._peaks = np.zeros((PEAK_DELAY, 5))
        self.stop = ControlledStop(n, round(cfg.supervisor.controlled_stop_s / period_s) if self.hexapod else 0)
        # identification tests (HOST_TEST, test bench only: chapter 6.4)
        ident = cfg.identification
        self.test = None if self.hexapod else IdentificationSignal(
            ident.force_gain_v_n, ident.force_filter_hz, ident.stroke_guard_m, cfg.actuator.stroke_m,
            cfg.pi.saturation_v, period_s)
        self.meas, _ = self.new_interfaces()            # the last cycle's measurements (events read them)
        self.dk_failures = 0
        self.reset_cycles = 0
        self._reset_pulse = False
        self.time_s = 0.0
        self.cycles = 0
        self.initialised = False
        self.reinitialise = False              # a RESET waits for a complete fresh set of measurements
        self.nodes_restart_requested = False   # a RESET was accepted: the NMT master starts nodes that rebooted
        self._warm_up()

    def new_interfaces(self) -> tuple[Measurements, ValveCommands]:
        """Measurements and commands sized for this rig (allocate once, reuse every cycle)."""
        return Measurements(self.n, self.n + (1 if self.hexapod else 0)), ValveCommands(self.n)

    def _warm_up(self) -> None:
        """Load every kernel the cycle calls now (configure): read from numba's cache inside a
        realtime cycle, each would stall the loop for milliseconds, past the valves' watchdog.
        Scratch arrays only; the state this touches is reset after."""
        n, ref = self.n, self.reference
        meas, cmd = self.new_interfaces()
        meas.position_m[:] = self.home_strokes
        meas.fresh[:] = True
        self.joint.update(meas.position_m, meas.fresh, meas.force_n, ref.yr, ref.ar, self.gravity_axial, self.tau_n,
                          False)
        self.node_monitor.check_heartbeats(meas.heartbeat_age_s)
        self.node_monitor.check_valves(meas.valve_state)
        self.frames.check(meas.fresh, meas.rejected, meas.sensor_fault)
        self.load_cells.update(meas.force_n, meas.fresh)
        self.limits.check_always(self.joint.u_v, self.joint.kalman_x, meas.force_n)
        self.limits.check_active(meas.position_m, self.joint.velocity_estimate, self.joint.error_m)
        self.plausibility.update(self.joint.u_v, meas.position_m)
        self.residuals.start(meas.position_m, meas.pressure_valid, meas.pa_pa, meas.pb_pa)
        self.residuals.update(self.spool_applied, meas.fresh, meas.position_m, meas.force_n, self.gravity_axial,
                              self.joint.acceleration_estimate, meas.pressure_fresh, meas.pa_pa, meas.pb_pa)
        self.supply.update(meas.ps_pa, meas.pressure_fresh)
        self.spool_check.update(self.spool_applied, self.spool_late, meas.spool, meas.fresh, meas.valve_state)
        self.chambers.start(meas.position_m)
        self.chambers.update(self.spool_applied, self.spool_late, meas.fresh, meas.position_m, meas.valve_state,
                             meas.pressure_fresh, meas.pa_pa, meas.pb_pa)
        valve_commands(VALVES_HOLD, self.joint.u_v, 1.0, False, -1, cmd.enable, cmd.hold, cmd.active, cmd.reset,
                       cmd.spool)
        ref.play(through_points(np.array([self.home_strokes, self.home_strokes + 1e-3]), 0.1, 0.2), [0], 0)
        ref.advance(1)
        ref.hold(np.zeros(n))
        home = tuple(self.geometry.home_position_m) if self.hexapod else (0.0, 0.0, float(self.home_strokes[0]))
        self.waypoints.check(self.home_strokes, home, (0.0, 0.0, 0.0), 1.0, 0.2, False, 0.0)   # a commit's kernels
        if self.hexapod:
            self.platform.estimate(self.home_strokes)
            self.platform.reset_reference(self.home_strokes)
            self.platform.reference_forces(self.home_strokes, ref.vr)
        # the cycle's own arrays: a view of another layout would compile a new signature
        self.computed_torque.update(self.platform, ref.yr, self.joint.velocity_estimate, self.joint.error_m, ref.vr,
                                    ref.ar, meas.force_n, cmd.spool)
        self.computed_torque.reset()
        if self.hexapod:
            self.platform.dk.reset()
        self.frames.reset()
        self.load_cells.reset()
        self.plausibility.reset()
        self.supply.reset()
        self.limits.recovery_left[0] = 0
        self.joint.reset(0.0)

    @property
    def state(self) -> State:
        return self.sup.state

    @property
    def active_waypoint(self) -> int:
        return self.reference.active_waypoint

    # -- host frames (events) ---------------------------------------------------------------
    def host_command(self, command: int, argument: int) -> Ack:
        if self.reinitialise and command in MOTION_COMMANDS:
            return Ack.BAD_STATE             # after RESET: not before every sensor has reported again
        result = self.sup.command(command, argument)
        if result is Ack.ACCEPTED:
            self._do_action()
        return result

    def waypoint_commit(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int) -> Ack:
        """HOST_WAYPOINT_TIME: check the staged pose and queue it (or say why not)."""
        ref = self.reference
        previous = ref.target() if ref.moving else ref.yr.copy()
        result = self.waypoints.commit(tag, seq, segment_time, accel_time, flags, self.state, previous,
                                       float(self.joint.mass_kg[0]))
        if (result is Ack.ACCEPTED and self.waypoints.queue[-1].flags & WaypointFlag.START
                and self.state is State.READY):
            self.host_command(Command.START, 0)
        return result

    def piston_force_n(self) -> float:
        """Leg 1's F_p from its latest chamber pressures (eq. 6.5)."""
        actuator = self.cfg.actuator
        return piston_force(self.meas.pa_pa[0], self.meas.pb_pa[0], actuator.piston_area_m2, actuator.area_ratio)

    def test_command(self, mode: int, valve_v: float, force_n: float, duration_s: float) -> Ack:
        """HOST_TEST (test bench): start an identification test from READY, or ABORT the one
        running (the leg then holds where it is)."""
        test = self.test
        if test is None or mode not in TEST_MODES or not all(map(math.isfinite, (valve_v, force_n, duration_s))):
            return Ack.BAD_ARGUMENT
        if mode == TestMode.ABORT:
            if not test.running:
                return Ack.BAD_STATE
            self._end_test()
            return Ack.ACCEPTED
        if duration_s <= 0.0 or abs(valve_v) > self.cfg.pi.saturation_v:
            return Ack.BAD_ARGUMENT
        if (self.state is not State.READY or self.reference.moving or self.reinitialise
                or not self.meas.pressure_valid[0]):
            return Ack.BAD_STATE
        test.start(mode, valve_v, force_n, duration_s, self.cycles, self.piston_force_n(),
                   float(self.joint.u_v[0]))           # the holding input: FORCE_SINE starts bumpless
        self.sup.start_running()
        return Ack.ACCEPTED

    def _end_test(self) -> None:
        self.test.stop()
        self.reference.hold(self.joint.position_estimate)
        self.sup.motion_done()

    def _do_action(self) -> None:
        action, self.sup.action = self.sup.action, Action.NONE
        cfg, ref = self.cfg, self.reference
        if self.test is not None and self.test.running and action is not Action.NONE:
            self.test.stop()                 # STOP (or anything else that moves the leg) ends a test
        if action is Action.ENABLE:
            ref.hold(self.limits.enable_target(self.meas.position_m))
            self.joint.integral[:] = 0.0
        elif action in (Action.HOME, Action.PARK):
            target = self.park_strokes if action is Action.PARK else self.home_strokes
            if not self.initialised:
                ref.yr[:] = self.meas.position_m
            ref.move(ref.yr, target, cfg.supervisor.homing_speed_m_s, cfg.supervisor.homing_accel_time_s, self.cycles)
        elif action is Action.START:
            self._start_queue()
        elif action is Action.STOP:
            ref.stop(cfg.supervisor.homing_accel_time_s, self.cycles)
        elif action is Action.RESET:
            self.reset_cycles = RESET_GRACE_CYCLES
            self.frames.reset()
            self.load_cells.reset()
            self.loop_monitor.reset()
            self.dk_failures = 0
            ref.trajectory = None
            # estimators and reference start again at the first complete set of fresh
            # measurements: after an outage the Kalman filter predicted on for seconds, and a
            # restarted sensor node may read elsewhere than the legs were last seen
            self.reinitialise = True
            self.nodes_restart_requested = True
        elif action is Action.CLEAR:
            self.waypoints.clear()

    def _start_queue(self) -> None:
        taken = self.waypoints.take(self.reference.yr)
        if taken is None:
            return
        trajectory, seqs = taken
        self.reference.play(trajectory, seqs, self.cycles)
        self.sup.start_running()

    def after_write(self, time_left_s: float = math.inf) -> None:
        """Host work that must not delay the cycle's VALVE_CMD: one waypoint commit, when
        `time_left_s` before the next SYNC leaves room for it."""
        self.host.run_after_write(self, time_left_s >= self.cfg.timing.commit_room_s)

    # -- lifecycle ----------------------------------------------------------------------------
    def activated(self, auto_enable: bool) -> None:
        """Activation is over (valves in HOLD): IDLE, or READY holding the measured position."""
        self.sup.booted(auto_enable)
        self._do_action()

    def shut_down(self) -> None:
        """The loop forces the valves to HOLD, then DISABLED: IDLE from here, so nothing judges
        the legs as if their valves still followed the controller."""
        self.sup.shut_down()

    def initialise(self, meas: Measurements, keep_load: bool = False) -> None:
        """First measurements are in (or the first after a RESET): estimators and the reference
        start at the measured state; `keep_load` keeps the load's mass estimate."""
        position = meas.position_m
        if self.hexapod:
            self.platform.estimate(position)
            self.platform.reset_reference(position)
        if keep_load:
            self.joint.restart_at(position, self.gravity_axial)
        else:
            self.joint.reset(position, self.gravity_axial)
        self.reference.yr[:] = position
        self.reference.hold_position[:] = position
        self.initialised = True

    # -- the cycle ------------------------------------------------------------------------------
    def update(self, meas: Measurements, cmd: ValveCommands) -> None:
        """One cycle: supervision, host frames, reference, estimation and control, limits,
        and the valve commands for the state the supervisor is in at its end."""
        sup, joint, ref = self.sup, self.joint, self.reference
        self.meas = meas
        # the loop and the nodes: before anything received late is acted on
        if sup.state is not State.BOOT:
            sup.fault(self.loop_monitor.check(meas.stalled, meas.overrun))
            sup.fault(self.node_monitor.check_heartbeats(meas.heartbeat_age_s))
        sup.fault(self.node_monitor.check_emergency(meas.emergency, meas.imu_emergency, self.reset_cycles > 0))
        # host frames received since the last update: carried out as between two cycles (a
        # trajectory they start is at t = T in this cycle, the rule a log's analysis rebuilds)
        self.host.run_before_update(self)
        self.cycles += 1
        self.time_s += self.period_s
        self._reset_pulse = self.reset_cycles == RESET_GRACE_CYCLES      # R high for one cycle
        if not self.initialised:
            if not meas.fresh.all():
                self._write(cmd)
                return
            self.initialise(meas)
        elif self.reinitialise and meas.fresh.all():
            self.initialise(meas, keep_load=True)
            self.reinitialise = False
        frames = self.frames.check(meas.fresh, meas.rejected, meas.sensor_fault)
        if frames is not Fault.NONE and sup.state not in LATCHED:      # the leg: an event's work
            sup.fault(frames, self.frames.leg_of(frames, meas.sensor_fault) + 1)
        frozen = self.load_cells.update(meas.force_n, meas.fresh)
        if frozen >= 0:
            sup.fault(Fault.LOAD_CELL, frozen + 1)
        if self.reset_cycles > 0:
            self.reset_cycles -= 1
        elif sup.state not in (State.FAULT, State.ESTOP, State.BOOT):
            sup.fault(self.node_monitor.check_valves(meas.valve_state))
        if self.hexapod:
            self._platform(meas)
        # reference
        active = sup.state in ACTIVE
        if self.stop.active and sup.state is not State.FAULT:
            self.stop.end()                          # an e-stop or a reset ends a controlled stop
        stopping = self.stop.active
        testing = self.test is not None and self.test.running
        if testing and not active:
            self.test.stop()                         # a fault or an e-stop ends it: valves hold
            testing = False
        if stopping:                                 # the healthy legs to the pose the locked leg allows
            self.stop.step(meas.position_m)
            ref.yr[:] = self.stop.target
            ref.vr[:] = 0.0
            ref.ar[:] = 0.0
        elif testing:                                # the test drives the valve: the loop follows the leg
            ref.follow(joint.position_estimate)
        elif active and ref.moving:
            if ref.advance(self.cycles):
                sup.motion_done()
                if self.waypoints.head_starts_now() and sup.state is State.READY:
                    self._start_queue()              # queued "start now": as soon as the last one ends
        elif active:
            ref.held()
        else:                                        # valves locked: follow the measurement
            ref.follow(joint.position_estimate)
        computed_torque = sup.controller == COMPUTED_TORQUE
        if self.hexapod and (sup.controller == MODEL_BASED or computed_torque):
            if not self.platform.reference_forces(ref.yr, ref.vr) and active:
                sup.fault(Fault.SINGULARITY)
        # estimation and control (computed torque: the joint pipeline estimates, its PI idles)
        if joint.mode != sup.controller:
            joint.set_mode(sup.controller)
        joint.update(meas.position_m, meas.fresh, meas.force_n, ref.yr, ref.ar, self.gravity_axial, self.tau_n,
                     (sup.state in ACTIVE and not computed_torque) or stopping)
        if computed_torque:
            if sup.state not in ACTIVE:
                self.computed_torque.reset()
            elif not self.computed_torque.update(self.platform, ref.yr, joint.velocity_estimate, joint.error_m, ref.vr,
                                                 ref.ar, meas.force_n, joint.u_v):
                sup.fault(Fault.SINGULARITY)
        if testing:
            u, done = self.test.output(self.cycles, meas.position_m[0], self.piston_force_n())
            joint.u_v[0] = u
            if done:
                self._end_test()
        self._residuals(meas, active and not testing)
        if stopping:
            self._stop_checks(meas)
        else:
            self._limits(meas, active)
        self._write(cmd)

    def _residuals(self, meas: Measurements, active: bool) -> None:
        """The actuators' residuals while the valves are ACTIVE: started where the legs are
        when they become ACTIVE; one leg beyond its threshold is that leg's fault, several at
        once the supply's."""
        res = self.residuals
        if not (active and self.cfg.residuals.enabled):
            self.residuals_running = False
            return
        if not self.residuals_running:
            res.start(meas.position_m, meas.pressure_valid, meas.pa_pa, meas.pb_pa)
            self.spool_check.start()
            self.chambers.start(meas.position_m)
            self.supply.reset()
            self.residuals_running = True
            return
        supply_faulty, lone_leg = self.supply.update(meas.ps_pa, meas.pressure_fresh)
        faulty = res.update(self.spool_applied, meas.fresh, meas.position_m, meas.force_n, self.gravity_axial,
                            self.joint.acceleration_estimate, meas.pressure_fresh, meas.pa_pa, meas.pb_pa)
        spools = self.spool_check.update(self.spool_applied, self.spool_late, meas.spool, meas.fresh,
                                         meas.valve_state) if self.cfg.residuals.spool_check else 0
        chambers = self.chambers.update(self.spool_applied, self.spool_late, meas.fresh, meas.position_m,
                                        meas.valve_state, meas.pressure_fresh, meas.pa_pa, meas.pb_pa)
        slot = self.cycles % PEAK_DELAY
        if self.sup.faults == 0:
            self.residual_peak = max(self.residual_peak, float(self._peaks[slot, 0]))
            self.supply_peak = max(self.supply_peak, float(self._peaks[slot, 1]))
            self.spool_peak = max(self.spool_peak, float(self._peaks[slot, 2]))
            self.attitude_peak = max(self.attitude_peak, float(self._peaks[slot, 3]))
            self.pressure_peak = max(self.pressure_peak, float(self._peaks[slot, 4]))
        self._peaks[slot, 0] = res.peak
        self._peaks[slot, 1] = self.supply.cycle_peak
        self._peaks[slot, 2] = self.spool_check.peak
        self._peaks[slot, 3] = self.attitude_check.ratio
        self._peaks[slot, 4] = self.chambers.peak
        if supply_faulty:
            self.sup.fault(Fault.SUPPLY_PRESSURE)
        elif lone_leg >= 0:
            self.sup.fault(Fault.SENSOR_FAULT, lone_leg + 1)
        elif spools:
            self._leg_fault(Fault.SPOOL_MISMATCH, self.spool_check.worst_leg)
        elif faulty >= self.cfg.residuals.supply_legs or chambers >= self.cfg.residuals.supply_legs:
            self.sup.fault(Fault.SUPPLY_PRESSURE)
        elif faulty:
            self._leg_fault(Fault.ACTUATOR_RESIDUAL, res.worst_leg)
        elif chambers and self.chambers.worst_leg >= 0:
            self._leg_fault(Fault.CHAMBER_PRESSURE, self.chambers.worst_leg)

    def _leg_fault(self, fault: Fault, leg: int) -> None:
        """A fault isolated to one leg: that leg holds while the others stop (the hexapod's
        controlled stop), then every valve."""
        if self.stop.cycles > 0 and self.sup.state in ACTIVE:
            self.stop.begin(leg, self.reference.yr, self.platform.jacobian_scaled)
        self.sup.fault(fault, leg + 1)

    def _stop_checks(self, meas: Measurements) -> None:
        """A controlled stop ends at once (every valve holds) on anything the limits see."""
        joint = self.joint
        if (self.limits.check_always(joint.u_v, joint.kalman_x, meas.force_n) is not Fault.NONE
                or self.node_monitor.check_valves(meas.valve_state) is not Fault.NONE
                or self.limits.check_active(meas.position_m, joint.velocity_estimate, joint.error_m)
                is not Fault.NONE):
            self.stop.end()

    def _platform(self, meas: Measurements) -> None:
        """Pose by direct kinematics, gravity along the legs; singularity and IMU checks."""
        sup, cfg = self.sup, self.cfg
        if self.platform.estimate(meas.position_m):
            self.dk_failures = 0
            if self.platform.det_ratio < cfg.kinematics.singularity_ratio_min:
                sup.fault(Fault.SINGULARITY)
            # the IMU's sample against the DK of the same SYNC: every leg's frame of this cycle
            if meas.attitude_fresh and meas.fresh.all() and self.attitude_check.update(
                    self.platform.rot, *meas.attitude_rad):
                sup.fault(Fault.ATTITUDE_MISMATCH)
        else:
            self.dk_failures += 1
            if self.dk_failures >= cfg.kinematics.dk_failures_fault:
                sup.fault(Fault.DK_FAILURE)

    def _limits(self, meas: Measurements, active: bool) -> None:
        sup, joint = self.sup, self.joint
        sup.fault(self.limits.check_always(joint.u_v, joint.kalman_x, meas.force_n))
        if not active:
            self.plausibility.reset()
            return
        sup.fault(self.limits.check_active(meas.position_m, joint.velocity_estimate, joint.error_m))
        if self.plausibility.update(joint.u_v, meas.position_m):
            sup.fault(Fault.MOTION_PLAUSIBILITY)

    def _write(self, cmd: ValveCommands) -> None:
        """Control words and spool setpoints for the state the supervisor is in now."""
        state = self.sup.state
        mode = (VALVES_DISABLED if state is State.ESTOP else
                VALVES_ACTIVE if state in ACTIVE or self.stop.active else VALVES_HOLD)
        valve_commands(mode, self.joint.u_v, self.cfg.actuator.valve_full_scale_v, self._reset_pulse, self.stop.leg,
                       cmd.enable, cmd.hold, cmd.active, cmd.reset, cmd.spool)
        np.copyto(self.spool_late, self.spool_applied)
        np.copyto(self.spool_applied, self.spool_sent)
        np.copyto(self.spool_sent, cmd.spool)


VALVES_DISABLED, VALVES_HOLD, VALVES_ACTIVE = 0, 1, 2


@njit(cache=True)
def valve_commands(mode, u_v, full_scale_v, reset_pulse, hold_leg, enable, hold, active, reset, spool):
    """CiA 408 control words and spool setpoints: DISABLED (power off), HOLD, or ACTIVE with
    the controller's input as the spool setpoint; ACTIVE with a non-finite input holds, and
    so does `hold_leg` (-1: none)."""
    finite = True
    for leg in range(u_v.shape[0]):
        finite = finite and math.isfinite(u_v[leg])
    for leg in range(u_v.shape[0]):
        enable[leg] = 0.0 if mode == VALVES_DISABLED else 1.0
        hold[leg] = enable[leg]
        go = mode == VALVES_ACTIVE and finite and leg != hold_leg
        active[leg] = 1.0 if go else 0.0
        spool[leg] = u_v[leg] / full_scale_v if go else 0.0
        reset[leg] = 1.0 if reset_pulse else 0.0
