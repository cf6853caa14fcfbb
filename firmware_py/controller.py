"""The controller of one rig without the bus: `update(meas, cmd)` is one cycle (supervision,
the host's frames, reference, estimation, control, limits, valve commands) on arrays made
here; it allocates nothing in the steady cycle.

Ports: `Measurements` in and `ValveCommands` out (protocol/interfaces.py) every cycle; the
host's frames in through `host` (hostlink.py), its acknowledgements out through it; and
`status` (status.py), what it says about itself, written at the end of every update. Its
parts are its own: nothing outside reaches into them.

The rig is an object (`rig_model.py`: the test bench or the hexapod); the controller kinds
are laws behind one interface (`motion_control/laws.py`) that write spool fractions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.checkpoint import Checkpoint
from firmware_py.config import ControllerConfig
from firmware_py.hostlink import HostLink
from firmware_py.mechanics.geometry import Geometry
from firmware_py.motion_control.excitation import TEST_MODES
from firmware_py.motion_control.joint_space import (
    ADAPTIVE,
    COMPUTED_TORQUE,
    MODEL_BASED,
    PI,
    JointController,
)
from firmware_py.motion_control.laws import ComputedTorqueLaw, JointSpaceLaw
from firmware_py.motion_control.reference import Reference
from firmware_py.motion_control.time_scaling import DISABLED, rule_of
from firmware_py.motion_control.trajectory import through_points
from firmware_py.rig_model import rig_model
from firmware_py.status import ControllerStatus
from firmware_py.supervision.diagnostics import FalseAlarmMargins
from firmware_py.supervision.monitors import FrameMonitor, LimitMonitor, LoopMonitor, NodeMonitor, all_set
from firmware_py.supervision.plausibility import FrozenLoadCells, MotionPlausibility, SupplyAtRest, SupplyPressure
from firmware_py.supervision.residuals import ActuatorResiduals, ChamberPrediction, SpoolResidual, sample_floor_pa
from firmware_py.supervision.stages import Stages, at_once
from firmware_py.supervision.stopping import ControlledStop
from firmware_py.supervision.supervisor import ACTIVE, LATCHED, Action, Supervisor
from firmware_py.supervision.waypoints import Chain, WaypointQueue
from physics import hydraulics as hy
from physics.actuator import piston_force
from physics.constants import BAR
from protocol.dbc import signal_scale
from protocol.enums import Ack, Command, Fault, State, TestMode, ValveState
from protocol.interfaces import Measurements, ValveCommands

MOTION_COMMANDS = (Command.ENABLE, Command.HOME, Command.PARK, Command.START)
RESET_GRACE_CYCLES = 4                 # valves need a SYNC or two to leave FAULT after R
# what the valves are told outside the laws: by the supervisor's state, or forced at shutdown
VALVES_DISABLED, VALVES_HOLD, VALVES_ACTIVE = 0, 1, 2
AT_REST = (State.IDLE, State.READY)            # no move plays: the valves draw no flow


class Controller:
    def __init__(self, cfg: ControllerConfig, rig: str, period_s: float, kind: int = PI,
                 geometry: Geometry | None = None):
        self.cfg, self.period_s = cfg, period_s
        self.rig = rig = rig_model(rig, cfg, period_s, geometry)
        self.n = n = rig.n
        self.full_scale_v = cfg.actuator.valve_full_scale_v
        self._full_scale = np.array(self.full_scale_v)          # 0-d: a ufunc converts no number per cycle
        self.joint = JointController(cfg, n, period_s, moving_mass_kg=rig.moving_mass_kg,
                                     mass_offset_kg=rig.mass_offset_kg, kp_factor=rig.kp_factor,
                                     ki_factor=rig.ki_factor, guide_friction=rig.guide_friction)
        self.laws = {k: JointSpaceLaw(k, self.joint, self.full_scale_v) for k in (PI, ADAPTIVE, MODEL_BASED)}
        self.laws[COMPUTED_TORQUE] = ComputedTorqueLaw(rig.computed_torque, self.joint, rig.platform,
                                                       rig.platform is not None)
        if int(kind) not in self.laws:
            raise ValueError(f"unknown controller kind {kind!r}")
        self.sup = Supervisor(kind)
        self.joint.set_mode(kind)
        self.reference = Reference(n, period_s, cfg.waypoints.queue + 2,
                                   rule_of(cfg, period_s) if rig.platform is not None else DISABLED)
        self.waypoints = WaypointQueue(cfg.waypoints, rig.check)
        self.host = HostLink()
        # supervision
        self.loop_monitor = LoopMonitor(cfg.supervisor)
        self.node_monitor = NodeMonitor(cfg.timing.heartbeat_timeout_s)
        self.frames = FrameMonitor(cfg.supervisor, n)
        self.limits = LimitMonitor(cfg.limits, n, rig.stroke_m)
        spool, cycles = rig.plausibility_window
        self.plausibility = MotionPlausibility(n, spool, cycles, cfg.plausibility.travel_m, rig.check.capacity,
                                               cfg.plausibility.overrun_share)
        res, encoder_m = cfg.residuals, cfg.actuator.encoder_resolution_m
        supply_pa = cfg.hydraulic_model.supply_pressure_pa
        self.load_cells = FrozenLoadCells(n, res.load_cell_noise_n, signal_scale("LEG_STATE_1", "FORCE"))
        # each actuator's chamber model against its load cell, while the valves are ACTIVE; the
        # cylinder's own stroke sets its chamber volumes
        self.residuals = ActuatorResiduals(n, cfg.hydraulics, cfg.friction.vector, period_s,
                                           rig.rod_mass_kg, res.column_stiffness_n_m, encoder_m, res.correction_gain,
                                           res.filter_s, res.persistence_cycles, res.flow_spread)
        self.spool_check = SpoolResidual(n, cfg.hydraulics, period_s, res.spool_floor, res.spool_lag_spread,
                                         res.spool_persistence_cycles, int(ValveState.ACTIVE))
        # each leg's chambers from one LEG_PRESSURE sample to the next
        floor_pa = sample_floor_pa(res.pressure_noise_pa, signal_scale("LEG_PRESSURE_1", "PA") * BAR)
        self.chambers = ChamberPrediction(n, cfg.hydraulics, period_s, encoder_m, res.flow_spread,
                                          res.leakage_spread, res.stiffness_spread, floor_pa,
                                          res.pressure_persistence_samples, res.pressure_carry,
                                          int(ValveState.ACTIVE))
        self.residuals_running = False
        # the valves' P-port transducers against the configured supply; their latest samples are
        # the supply the chamber models and computed torque run on (`SupplyPressure.latest_pa`)
        self.supply = SupplyPressure(n, supply_pa, cfg.hydraulics[hy.HP_TANK], res.flow_spread, res.supply_legs)
        # after a move, not at rest until the pump has refilled the accumulator (ControllerConfig.supply_refill_s)
        self.supply_at_rest = SupplyAtRest(n, supply_pa, res.supply_tolerance_pa, res.supply_legs,
                                           round(cfg.supply_refill_s / period_s))
        self.resting, self.rest_peak = False, 0.0     # the at-rest check judging, its ratio this cycle
        self.margins = FalseAlarmMargins()
        self.stop = ControlledStop(n, rig.stop_cycles)
        # the valve input the laws write (fraction of full input), and what was sent: the last
        # cycle's (applied at this SYNC), the one before (applied over the period this cycle's
        # measurements close) and the one before that (applied then when the other came late)
        self.spool_cmd = np.zeros(n)
        self.spool_sent = np.zeros(n)
        self.spool_applied = np.zeros(n)
        self.spool_late = np.zeros(n)
        self.meas, _ = self.new_interfaces()            # the last cycle's measurements (events read them)
        self.valves_forced: int | None = None           # shutdown: VALVES_HOLD, then VALVES_DISABLED
        self.reset_cycles = 0
        self._reset_pulse = False
        self.time_s = 0.0
        self.cycles = 0
        self.restart_requests = 0
        # the oil the last trajectory left drawn from the supply when it ended, and when: the
        # pump refills it while nothing moves (the capacity check starts the next one from it)
        self._drawn_at_end_m3, self._ended_s = 0.0, 0.0
        self._pump_m3_s = cfg.power_unit.pump_flow_m3_s
        self.initialised = False
        self.reinitialise = False              # a RESET waits for a complete fresh set of measurements
        self.status = self._new_status()
        self._warm_up()
        self._publish()

    def _new_status(self) -> ControllerStatus:
        rig, joint = self.rig, self.joint
        platform = rig.platform
        return ControllerStatus(
            rig=rig.name, n_legs=self.n, n_nodes=rig.n_nodes, kind=self.sup.controller, reference_m=self.reference.yr,
            hold_m=self.reference.hold_position, position_m=joint.position_estimate, error_m=joint.error_m,
            spool=self.spool_cmd, load_mass_kg=joint.mass_kg, load_pressure_pa=joint.load_pressure_pa,
            friction_n=joint.friction_n, residual_ratio=self.residuals.ratio,
            missing_in_row=self.frames.missing, rejected_in_row=self.frames.rejected,
            pose=platform.dk.pose if platform is not None else None,
            reference_pose=platform.ref_dk.pose if platform is not None else None, margins=self.margins,
            supply_configured_pa=self.supply_at_rest.nominal_pa, payload_com_m=rig.payload_com_m)

    def new_interfaces(self) -> tuple[Measurements, ValveCommands]:
        """Measurements and commands sized for this rig (allocate once, reuse every cycle)."""
        return Measurements(self.n, self.rig.n_nodes), ValveCommands(self.n)

    def _warm_up(self) -> None:
        """Load every kernel the cycle calls now (configure): read from numba's cache inside a
        realtime cycle, each would stall the loop for milliseconds, past the valves' watchdog.
        Scratch arrays only; the state this touches is reset after."""
        n, ref, rig = self.n, self.reference, self.rig
        meas, cmd = self.new_interfaces()
        meas.position_m[:] = rig.home_strokes
        meas.fresh.fill(True)
        self.joint.update(meas.position_m, meas.fresh, meas.force_n, ref.yr, ref.ar, rig.gravity_axial, rig.tau_n,
                          False)
        self.node_monitor.check_heartbeats(meas.heartbeat_age_s)
        self.node_monitor.check_valves(meas.valve_state)
        self.frames.check(meas.fresh, meas.rejected, meas.sensor_fault)
        self.load_cells.update(meas.force_n, meas.fresh)
        self.limits.check_always(self.spool_cmd, self.joint.kalman_x, meas.force_n)
        self.limits.check_active(meas.position_m, self.joint.velocity_estimate, self.joint.error_m)
        rig.pose_error_exceeds(self.joint.error_m)
        self.plausibility.update(self.spool_cmd, meas.position_m, meas.force_n, self.joint.velocity_estimate)
        self.residuals.start(meas.position_m, meas.pressure_valid, meas.pa_pa, meas.pb_pa)
        self.residuals.update(self.spool_applied, meas.fresh, meas.position_m, meas.force_n, rig.gravity_axial,
                              self.joint.acceleration_estimate, meas.pressure_fresh, meas.pa_pa, meas.pb_pa,
                              self.supply.latest_pa)
        self.supply.update(meas.ps_pa, meas.pressure_fresh)
        self.supply_at_rest.update(meas.ps_pa, meas.pressure_fresh)
        self.spool_check.update(self.spool_applied, self.spool_late, meas.spool, meas.fresh, meas.valve_state)
        self.chambers.start(meas.position_m)
        self.chambers.update(self.spool_applied, self.spool_late, meas.fresh, meas.position_m, meas.valve_state,
                             meas.pressure_fresh, meas.pa_pa, meas.pb_pa, self.supply.latest_pa)
        valve_commands(VALVES_HOLD, self.spool_cmd, False, -1, cmd.enable, cmd.hold, cmd.active, cmd.reset,
                       cmd.spool)
        ref.play(through_points(np.array([rig.home_strokes, rig.home_strokes + 1e-3]), 0.1, 0.2), [0], 0)
        ref.advance(self.spool_sent)
        ref.clock.warm_up(self.spool_sent)
        ref.clock.observe(meas.ps_pa, meas.pressure_fresh)
        ref.hold(np.zeros(n))
        self.waypoints.check(Chain([rig.home_strokes], [0.2], [1.0]), rig.home_pose, (0.0, 0.0, 0.0), False,
                             0.0)   # a commit's
        rig.warm_up(ref)
        # the cycle's own arrays: a view of another layout would compile a new signature
        law = self.laws[COMPUTED_TORQUE]
        law.update(ref, meas.force_n, self.supply.latest_pa, self.spool_cmd)
        law.reset()
        self.spool_cmd.fill(0.0)
        rig.forget()
        self.frames.reset()
        self.load_cells.reset()
        self.plausibility.reset()
        self.supply.reset()
        self.supply_at_rest.reset()
        self.limits.recovery_left[0] = 0
        self.joint.reset(0.0)

    @property
    def state(self) -> State:
        return self.sup.state

    # -- lifecycle ----------------------------------------------------------------------------
    def reset_valves(self) -> None:
        """Activation: the first cycles send the valves a Reset pulse (clearing faults left by
        an earlier session) and wait for them to leave FAULT."""
        self.reset_cycles = RESET_GRACE_CYCLES

    def activated(self, auto_enable: bool) -> None:
        """Activation is over (valves in HOLD): IDLE, or READY holding the measured position."""
        self.sup.booted(auto_enable)
        self._do_action()
        self._publish()

    def shut_down(self) -> None:
        """The daemon stops: the valves HOLD from the next write on, whatever the state; IDLE
        from here, so nothing judges the legs as if their valves still followed the controller."""
        self.sup.shut_down()
        self.valves_forced = VALVES_HOLD
        self._publish()

    def power_off(self) -> None:
        """The last cycles before the daemon exits: the valves' power stages off."""
        self.valves_forced = VALVES_DISABLED

    def initialise(self, meas: Measurements, keep_load: bool = False) -> None:
        """First measurements are in (or the first after a RESET): estimators and the reference
        start at the measured state; `keep_load` keeps the load's mass estimate."""
        position = meas.position_m
        self.rig.initialise(position)
        if keep_load:
            self.joint.restart_at(position, self.rig.gravity_axial)
        else:
            self.joint.reset(position, self.rig.gravity_axial)
        self.reference.yr[:] = position
        self.reference.hold_position[:] = position
        self.initialised = True

    # -- host frames (events: HostLink carries them out) ------------------------------------------
    def host_command(self, command: int, argument: int) -> Ack:
        if self.reinitialise and command in MOTION_COMMANDS:
            return Ack.BAD_STATE             # after RESET: not before every sensor has reported again
        if (command == Command.ENABLE and self.sup.state is State.IDLE
                and not self.rig.check.holds(self.meas.position_m, float(self.joint.mass_kg[0]))):
            return Ack.BEYOND_CAPACITY       # the valves stay in HOLD: sealed, they hold beyond the supply
        if command == Command.START and self.sup.state is State.READY and not self.waypoints.head_complete():
            return Ack.INCOMPLETE            # a trajectory plays only once its LAST is queued
        result = self.sup.command(command, argument)
        if result is Ack.ACCEPTED:
            self._do_action()
        self._publish()
        return result

    def stage_position(self, tag: int, x: float, y: float, z: float) -> None:
        """HOST_WAYPOINT_POS: a waypoint's position, staged under its TAG."""
        self.waypoints.stage_position(tag, x, y, z)

    def stage_rotation(self, tag: int, roll: float, pitch: float, yaw: float) -> None:
        """HOST_WAYPOINT_ROT: its orientation."""
        self.waypoints.stage_rotation(tag, roll, pitch, yaw)

    def waypoint_commit(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int) -> Ack:
        """HOST_WAYPOINT_TIME: check the staged pose and queue it (or say why not), at once."""
        return at_once(self.waypoint_commit_stages(tag, seq, segment_time, accel_time, flags))

    def _commit_context(self) -> tuple:
        """What a waypoint's check starts from now: (state, the joint position its segment
        starts from, the load, the oil the supply misses then, the running motion's last
        waypoint (the lag it leaves; at rest None))."""
        ref = self.reference
        previous = ref.target() if ref.moving else ref.yr.copy()
        refilled = self._pump_m3_s * (self.time_s - self._ended_s)
        drawn = self.waypoints.taken_drawn_m3 if ref.moving else max(self._drawn_at_end_m3 - refilled, 0.0)
        running = self.waypoints.taken_last if ref.moving else None
        return self.state, previous, float(self.joint.mass_kg[0]), drawn, running

    def waypoint_commit_stages(self, tag: int, seq: int, segment_time: float, accel_time: float,
                               flags: int) -> Stages[Ack]:
        """`waypoint_commit` in stages (the host link spreads them over the cycles' slack)."""
        result = yield from self.waypoints.commit_stages(tag, seq, segment_time, accel_time, flags,
                                                         self._commit_context)
        if result is Ack.ACCEPTED and self.waypoints.head_starts_now() and self.state is State.READY:
            self.host_command(Command.START, 0)
        self._publish()
        return result

    def piston_force_n(self) -> float:
        """Leg 1's F_p from its latest chamber pressures (eq. 6.5)."""
        actuator = self.cfg.actuator
        return piston_force(self.meas.pa_pa[0], self.meas.pb_pa[0], actuator.piston_area_m2, actuator.area_ratio)

    def test_command(self, mode: int, valve_v: float, force_n: float, duration_s: float) -> Ack:
        """HOST_TEST (test bench): start an identification test from READY, or ABORT the one
        running (the leg then holds where it is)."""
        test = self.rig.excitation
        if test is None or mode not in TEST_MODES or not all(map(math.isfinite, (valve_v, force_n, duration_s))):
            return Ack.BAD_ARGUMENT
        if mode == TestMode.ABORT:
            if not test.running:
                return Ack.BAD_STATE
            self._end_test()
            self._publish()
            return Ack.ACCEPTED
        if duration_s <= 0.0 or abs(valve_v) > self.cfg.pi.saturation_v:
            return Ack.BAD_ARGUMENT
        if (self.state is not State.READY or self.reference.moving or self.reinitialise
                or not self.meas.pressure_valid[0]):
            return Ack.BAD_STATE
        # the holding input: FORCE_SINE starts bumpless
        test.start(mode, valve_v, force_n, duration_s, self.cycles, self.piston_force_n(),
                   float(self.spool_cmd[0]) * self.full_scale_v)
        self.sup.start_running()
        self._publish()
        return Ack.ACCEPTED

    def _end_test(self) -> None:
        self.rig.excitation.stop()
        self.reference.hold(self.joint.position_estimate)
        self.sup.motion_done()

    def _do_action(self) -> None:
        action, self.sup.action = self.sup.action, Action.NONE
        cfg, ref = self.cfg, self.reference
        test = self.rig.excitation
        if test is not None and test.running and action is not Action.NONE:
            test.stop()                      # STOP (or anything else that moves the leg) ends a test
        if action is Action.ENABLE:
            ref.hold(self.limits.enable_target(self.meas.position_m))
            self.joint.integral.fill(0.0)
        elif action in (Action.HOME, Action.PARK):
            target = self.rig.park_strokes if action is Action.PARK else self.rig.home_strokes
            if not self.initialised:
                ref.yr[:] = self.meas.position_m
            ref.move(ref.yr, target, cfg.supervisor.homing_speed_m_s, cfg.supervisor.homing_accel_time_s,
                     self.cycles)
        elif action is Action.START:
            self._start_queue()
        elif action is Action.STOP:
            ref.stop(cfg.supervisor.homing_accel_time_s, self.cycles)
        elif action is Action.RESET:
            self.reset_cycles = RESET_GRACE_CYCLES
            self.frames.reset()
            self.load_cells.reset()
            self.loop_monitor.reset()
            self.rig.reset()
            ref.trajectory = None
            # estimators and reference start again at the first complete set of fresh
            # measurements: after an outage the Kalman filter predicted on for seconds, and a
            # restarted sensor node may read elsewhere than the legs were last seen
            self.reinitialise = True
            self.restart_requests += 1       # the NMT master starts nodes that rebooted
        elif action is Action.CLEAR:
            self.waypoints.clear()

    def _start_queue(self) -> None:
        taken = self.waypoints.take(self.reference.yr)
        if taken is None:
            return
        trajectory, seqs = taken
        self.reference.play(trajectory, seqs, self.cycles)
        self.sup.start_running()

    def after_write(self, time_left_s: float = math.inf, clock=None) -> None:
        """Host work that must not delay the cycle's VALVE_CMD: the front waypoint commit's
        stages while the time left before the next SYNC (`time_left_s` now, less what they
        take by `clock`) leaves `commit_room_us` for another. A stage forced by a long wait
        skips a cycle that follows an overrun: a commit never makes overruns in a row."""
        self.host.run_after_write(self, time_left_s, self.cfg.timing.commit_room_s, clock, not self.meas.overrun)

    # -- the cycle ------------------------------------------------------------------------------
    def update(self, meas: Measurements, cmd: ValveCommands) -> None:
        """One cycle: supervision, host frames, reference, estimation and control, limits,
        and the valve commands for the state the supervisor is in at its end."""
        sup, joint, ref, rig = self.sup, self.joint, self.reference, self.rig
        self.meas = meas
        # the loop and the nodes: before anything received late is acted on
        if sup.state is not State.BOOT:
            sup.fault(self.loop_monitor.check(meas.stalled, meas.overrun))
            sup.fault(self.node_monitor.check_heartbeats(meas.heartbeat_age_s))
        sup.fault(self.node_monitor.check_emergency(meas.emergency, meas.sensor_emergency, self.reset_cycles > 0))
        # host frames received since the last update: carried out as between two cycles (a
        # trajectory they start is at t = T in this cycle, the rule a log's analysis rebuilds)
        self.host.run_before_update(self)
        self.cycles += 1
        self.time_s += self.period_s
        self._reset_pulse = self.reset_cycles == RESET_GRACE_CYCLES      # R high for one cycle
        if not self.initialised:
            if not all_set(meas.fresh):
                self._write(cmd)
                self._publish()
                return
            self.initialise(meas)
        elif self.reinitialise and all_set(meas.fresh):
            self.initialise(meas, keep_load=True)
            self.reinitialise = False
        if meas.nodes_starting:             # silent until the NMT master starts them: not a timeout
            self.frames.reset()
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
        sup.fault(rig.estimate(meas))
        rig.update_payload(meas, self.reference.ar, sup.state not in (State.FAULT, State.ESTOP, State.BOOT))
        # reference
        ref.clock.observe(meas.ps_pa, meas.pressure_fresh)
        active = sup.state in ACTIVE
        if self.stop.active and sup.state is not State.FAULT:
            self.stop.end()                          # an e-stop or a reset ends a controlled stop
        stopping = self.stop.active
        test = rig.excitation
        testing = test is not None and test.running
        if testing and not active:
            test.stop()                              # a fault or an e-stop ends it: valves hold
            testing = False
        self._supply_at_rest(meas, testing)
        if stopping:                                 # the healthy legs to the pose the locked leg allows
            self.stop.step(meas.position_m)
            ref.yr[:] = self.stop.target
            ref.vr.fill(0.0)
            ref.ar.fill(0.0)
        elif testing:                                # the test drives the valve: the loop follows the leg
            ref.follow(joint.position_estimate)
        elif active and ref.moving:
            if ref.advance(self.spool_sent):
                sup.motion_done()
                self._drawn_at_end_m3, self._ended_s = self.waypoints.taken_drawn_m3, self.time_s
                if self.waypoints.head_starts_now() and sup.state is State.READY:
                    self._start_queue()              # queued "start now": as soon as the last one ends
        elif active:
            ref.held()
        else:                                        # valves locked: follow the measurement
            ref.follow(joint.position_estimate)
        law = self.laws[sup.controller]
        if law.needs_reference_forces and not rig.reference_forces(ref) and active:
            sup.fault(Fault.SINGULARITY)
        # estimation and control: every kind estimates with the joint pipeline; the thesis's
        # kinds also run its law, as does a controlled stop
        if joint.mode != sup.controller:              # a selection: the joint integral carries over
            joint.set_mode(sup.controller)              # (bumpless); the new law starts from rest, not
            law.reset()                                 # from its state when last deselected
        following = sup.state in ACTIVE            # (a fault above may have ended `active`)
        joint.update(meas.position_m, meas.fresh, meas.force_n, ref.yr, ref.ar, rig.gravity_axial, rig.tau_n,
                     (following and law.runs_joint_law) or stopping)
        if following:
            if not law.update(ref, meas.force_n, self.supply.latest_pa, self.spool_cmd):
                sup.fault(Fault.SINGULARITY)
                self.spool_cmd.fill(0.0)
        else:
            law.reset()
            # a controlled stop runs the joint pipeline's law; locked valves get its idle 0
            np.divide(joint.u_v, self._full_scale, out=self.spool_cmd)
        if testing:
            u, done = test.output(self.cycles, meas.position_m[0], self.piston_force_n())
            self.spool_cmd[0] = u / self.full_scale_v
            if done:
                self._end_test()
        self._residuals(meas, active and not testing)
        if stopping:
            self._stop_checks(meas)
        else:
            self._limits(meas, active)
        self._write(cmd)
        self._publish()

    def _residuals(self, meas: Measurements, active: bool) -> None:
        """The actuators' residuals while the valves are ACTIVE: started where the legs are
        when they become ACTIVE; one leg beyond its threshold is that leg's fault, several at
        once the supply's."""
        res, res_cfg = self.residuals, self.cfg.residuals
        if not (active and res_cfg.enabled):
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
        faulty = res.update(self.spool_applied, meas.fresh, meas.position_m, meas.force_n, self.rig.gravity_axial,
                            self.joint.acceleration_estimate, meas.pressure_fresh, meas.pa_pa, meas.pb_pa,
                            self.supply.latest_pa)
        spools = self.spool_check.update(self.spool_applied, self.spool_late, meas.spool, meas.fresh,
                                         meas.valve_state) if res_cfg.spool_check else 0
        chambers = self.chambers.update(self.spool_applied, self.spool_late, meas.fresh, meas.position_m,
                                        meas.valve_state, meas.pressure_fresh, meas.pa_pa, meas.pb_pa,
                                        self.supply.latest_pa)
        attitude = self.rig.attitude_check.ratio if self.rig.platform is not None else 0.0
        self.margins.record(self.cycles, self.sup.faults > 0, res.peak, max(self.supply.cycle_peak, self.rest_peak),
                            self.spool_check.peak,
                            attitude, self.chambers.peak)
        if supply_faulty:
            self.sup.fault(Fault.SUPPLY_PRESSURE)
        elif lone_leg >= 0:
            self.sup.fault(Fault.SENSOR_FAULT, lone_leg + 1)
        elif spools:
            self._leg_fault(Fault.SPOOL_MISMATCH, self.spool_check.worst_leg)
        elif faulty >= res_cfg.supply_legs or chambers >= res_cfg.supply_legs:
            self.sup.fault(Fault.SUPPLY_PRESSURE)
        elif faulty:
            self._leg_fault(Fault.ACTUATOR_RESIDUAL, res.worst_leg)
        elif chambers and self.chambers.worst_leg >= 0 and self.spool_check.above[self.chambers.worst_leg] == 0:
            # a spool off its band explains the chambers (they follow the spool, not the
            # command): the spool check names it within its persistence
            self._leg_fault(Fault.CHAMBER_PRESSURE, self.chambers.worst_leg)

    def _supply_at_rest(self, meas: Measurements, testing: bool) -> None:
        """The P-port transducers against the configured supply while no move plays (IDLE or
        READY): off on `supply_legs` legs is the power unit's SUPPLY_PRESSURE, said as such
        before the chamber and flow checks, which assume that supply, can name a leg's seal;
        one leg off alone for two samples is its transducer's SENSOR_FAULT."""
        check = self.supply_at_rest
        if not (self.cfg.residuals.enabled and self.sup.state in AT_REST and not self.reference.moving
                and not testing):
            if self.resting:                         # a move starts: its samples are not at rest
                check.moved()
                self.resting, self.rest_peak = False, 0.0
            return
        self.resting = True
        off, lone = check.update(meas.ps_pa, meas.pressure_fresh)
        self.rest_peak = check.peak
        if off:
            self.sup.fault(Fault.SUPPLY_PRESSURE)
        elif lone >= 0:
            self.sup.fault(Fault.SENSOR_FAULT, lone + 1)

    def _leg_fault(self, fault: Fault, leg: int) -> None:
        """A fault isolated to one leg: that leg holds while the others stop (the hexapod's
        controlled stop), then every valve."""
        if self.stop.cycles > 0 and self.sup.state in ACTIVE:
            self.stop.begin(leg, self.reference.yr, self.rig.jacobian_scaled)
        self.sup.fault(fault, leg + 1)

    def _stop_checks(self, meas: Measurements) -> None:
        """A controlled stop ends at once (every valve holds) on anything the limits see."""
        joint = self.joint
        if (self.limits.check_always(self.spool_cmd, joint.kalman_x, meas.force_n) is not Fault.NONE
                or self.node_monitor.check_valves(meas.valve_state) is not Fault.NONE
                or self.limits.check_active(meas.position_m, joint.velocity_estimate, joint.error_m)
                is not Fault.NONE):
            self.stop.end()

    def _limits(self, meas: Measurements, active: bool) -> None:
        sup, joint = self.sup, self.joint
        sup.fault(self.limits.check_always(self.spool_cmd, joint.kalman_x, meas.force_n))
        if not active:
            self.plausibility.reset()
            return
        sup.fault(self.limits.check_active(meas.position_m, joint.velocity_estimate, joint.error_m))
        if self.rig.pose_error_exceeds(joint.error_m):
            sup.fault(Fault.TRACKING_ERROR)
        if self.plausibility.update(self.spool_cmd, meas.position_m, meas.force_n, joint.velocity_estimate):
            sup.fault(Fault.MOTION_PLAUSIBILITY)

    def _write(self, cmd: ValveCommands) -> None:
        """Control words and spool setpoints for the state the supervisor is in now (or what
        the shutdown forces)."""
        state = self.sup.state
        if self.valves_forced is not None:
            mode = self.valves_forced
        else:
            mode = (VALVES_DISABLED if state is State.ESTOP else
                    VALVES_ACTIVE if state in ACTIVE or self.stop.active else VALVES_HOLD)
        valve_commands(mode, self.spool_cmd, self._reset_pulse, self.stop.leg, cmd.enable, cmd.hold, cmd.active,
                       cmd.reset, cmd.spool)
        np.copyto(self.spool_late, self.spool_applied)
        np.copyto(self.spool_applied, self.spool_sent)
        np.copyto(self.spool_sent, cmd.spool)

    def _publish(self) -> None:
        """The status of this cycle (no allocation: scalars and views made once)."""
        s, sup, reference = self.status, self.sup, self.reference
        s.state, s.fault, s.fault_leg, s.kind = sup.state, sup.fault_code, sup.fault_leg, sup.controller
        s.active_waypoint, s.moving = reference.active_waypoint, reference.trajectory is not None
        # played: advanced at least once, and not a fault's left-over trajectory
        clock = reference.clock
        playing = s.moving and sup.state in ACTIVE and clock.ticks > 0
        s.time_scaled, s.time_rate = clock.scaling and playing, clock.rate_fraction if playing else 1.0
        s.motion_time_periods = clock.cycles() if playing else 0.0
        s.queue_free = self.waypoints.free()
        s.cycles, s.faults, s.restart_requests = self.cycles, sup.faults, self.restart_requests
        test = self.rig.excitation
        s.testing = test is not None and test.running
        s.initialised = self.initialised and not self.reinitialise
        s.overruns_in_row = self.loop_monitor.overruns_in_row
        s.supply_measured_pa = self.supply_at_rest.measured_pa
        if self.rig.platform is not None:
            s.attitude_mismatch_rad = self.rig.attitude_check.angle_rad
            s.payload_mass_kg = self.rig.payload_mass_kg

    # -- linearisation (hil/design/closed_loop.py) ----------------------------------------------
    def checkpoint(self) -> Checkpoint:
        """Everything this controller holds, to `restore()` later."""
        return Checkpoint(self)

    def dynamic_state(self) -> list[np.ndarray]:
        """The controller's dynamic state as views, for a linearisation by differences: the
        legs' Kalman filters, and the running law's own (computed torque: its integral, where
        the stiff directions' velocity share counts from, the twist's two low-passes (their
        third column is the last input) and the legs' positions it differences)."""
        law = self.laws[self.sup.controller]
        views = [self.joint.kalman_x]
        if law is self.laws[COMPUTED_TORQUE]:
            ct = self.rig.computed_torque
            views += [ct.integral, ct.stiff_origin, ct.twist_filter_state[:, :2], ct.twist_rest_filter_state[:, :2],
                      ct.position_prev]
        return views


@njit(cache=True)
def valve_commands(mode, spool_cmd, reset_pulse, hold_leg, enable, hold, active, reset, spool):
    """CiA 408 control words and spool setpoints: DISABLED (power off), HOLD, or ACTIVE with
    the controller's input as the spool setpoint; ACTIVE with a non-finite input holds, and
    so does `hold_leg` (-1: none)."""
    finite = True
    for leg in range(spool_cmd.shape[0]):
        finite = finite and math.isfinite(spool_cmd[leg])
    for leg in range(spool_cmd.shape[0]):
        enable[leg] = 0.0 if mode == VALVES_DISABLED else 1.0
        hold[leg] = enable[leg]
        go = mode == VALVES_ACTIVE and finite and leg != hold_leg
        active[leg] = 1.0 if go else 0.0
        spool[leg] = spool_cmd[leg] if go else 0.0
        reset[leg] = 1.0 if reset_pulse else 0.0
