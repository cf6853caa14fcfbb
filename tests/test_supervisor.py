"""Supervisor and host interface: state transitions with their reset paths, faults from
the bus, e-stop in the same cycle, waypoint checks with reason codes (a rejected waypoint
never moves anything). Through the real loop and ctl, with the in-process fake bus."""

import math
import time

import can
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from firmware_py.hostlink import COMMIT_MAX_WAIT_CYCLES
from firmware_py.mechanics.kinematics import DirectKinematics, ik_batch
from firmware_py.mechanics.rotation import quat_to_rpy
from firmware_py.supervision.supervisor import Supervisor
from protocol.dbc import load_database
from protocol.enums import Ack, AckKind, Command, EmcyCode, Fault, State
from protocol.nodes import CONTROLLER_NODE, IMU_NODE
from tests.rig_loop import cycles, cycles_until_fault, make_loop, send_waypoint, valve_words


def test_state_machine_table():
    s = Supervisor()
    assert s.state is State.BOOT
    s.booted(auto_enable=False)
    assert s.state is State.IDLE
    assert s.command(Command.START, 0) is Ack.BAD_STATE
    assert s.command(Command.ENABLE, 0) is Ack.ACCEPTED and s.state is State.READY
    assert s.command(Command.SELECT_CONTROLLER, 4) is Ack.BAD_ARGUMENT
    assert s.command(Command.SELECT_CONTROLLER, 2) is Ack.ACCEPTED and s.controller == 2
    assert s.command(Command.HOME, 0) is Ack.ACCEPTED and s.state is State.HOMING
    assert s.command(Command.SELECT_CONTROLLER, 0) is Ack.BAD_STATE
    s.motion_done()
    assert s.state is State.READY
    assert s.command(Command.PARK, 0) is Ack.ACCEPTED
    s.motion_done()
    assert s.state is State.IDLE                       # parked: valves hold
    assert s.command(Command.RESET, 0) is Ack.BAD_STATE
    assert s.command(99, 0) is Ack.UNKNOWN_COMMAND
    s.fault(Fault.SENSOR_TIMEOUT)
    s.fault(Fault.E2E_ERROR)                            # the first fault stays latched
    assert s.state is State.FAULT and s.fault_code is Fault.SENSOR_TIMEOUT
    assert s.command(Command.ENABLE, 0) is Ack.BAD_STATE
    assert s.command(Command.RESET, 0) is Ack.ACCEPTED and s.state is State.IDLE
    assert s.fault_code is Fault.NONE
    assert s.command(Command.ESTOP, 0) is Ack.ACCEPTED and s.state is State.ESTOP
    s.fault(Fault.OVERRUN)
    assert s.fault_code is Fault.ESTOP
    assert s.command(Command.RESET, 0) is Ack.ACCEPTED and s.state is State.IDLE


@pytest.mark.parametrize("rig", ["testbench", "hexapod"])
def test_activation_enables_and_holds_position(rig):
    loop, ctl, bus = make_loop(rig, "pi")
    assert ctl.state is State.READY
    start = list(bus.y)
    cycles(loop, 500)
    assert all(v == 3 for v in bus.valve)                      # ACTIVE
    assert np.max(np.abs(np.array(bus.y) - start)) < 0.5e-3
    assert ctl.sup.fault_code is Fault.NONE


def test_estop_disables_valves_in_the_same_cycle_and_reset_recovers():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 50)
    assert ctl.host_command(Command.ESTOP, 0) is Ack.ACCEPTED
    loop.cycle()
    d, h, m, spool = valve_words(loop)
    assert (d, h, m, spool) == (0, 0, 0, 0)                  # written in the cycle that saw the command
    cycles(loop, 3)
    assert bus.valve == [1]                                  # DISABLED at the next SYNC
    assert ctl.host_command(Command.ENABLE, 0) is Ack.BAD_STATE
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED
    loop.cycle()
    assert loop.out_cmd[0].values[loop.out_cmd[0].index["CW_R"]] == 1.0    # the reset pulse
    cycles(loop, 3)
    assert ctl.state is State.IDLE and bus.valve == [2]     # HOLD
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    cycles(loop, 5)
    assert ctl.state is State.READY and bus.valve == [3]


def test_missing_sensor_frames_fault_after_the_configured_count_then_reset():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    bus.silent.add(0)
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault - 1)
    assert ctl.state is State.READY                          # transient: still running
    loop.cycle()
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.SENSOR_TIMEOUT
    d, h, m, _ = valve_words(loop)
    assert (d, h, m) == (1, 1, 0)                             # FAULT holds the valves
    assert all(math.isfinite(v) for v in ctl.joint.st[0])
    bus.silent.clear()
    cycles(loop, 5)
    assert ctl.state is State.FAULT                          # needs an explicit reset
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED
    cycles(loop, 1)                                           # every sensor reported: estimators restart
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.state is State.READY


def test_e2e_corrupted_frames_are_counted_and_fault():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    bus.corrupt.add(0)
    cycles(loop, ctl.cfg.supervisor.e2e_errors_fault)
    assert loop.stats.e2e_errors == ctl.cfg.supervisor.e2e_errors_fault
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.E2E_ERROR


def test_valve_fault_state_faults_the_controller():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 10)
    bus.valve[0] = 4                                          # FAULT_HOLD reported in LEG_STATE
    bus.latched[0] = None
    loop.cycle()
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.VALVE_FAULT



def controller_emcy(loop, bus) -> tuple[int, dict]:
    """How many EMCY_16 the controller sent, and the last one decoded."""
    message = load_database().get_message_by_name(f"EMCY_{CONTROLLER_NODE}")     # stock cantools
    data = bus.last_sent.get(message.frame_id)
    return bus.sent[message.frame_id], (message.decode(data, decode_choices=False) if data is not None else {})


def test_the_controller_sends_its_emcy_when_it_latches_and_when_a_reset_clears():
    """A CANopen watcher learns of a controller fault: EMCY_16 with the CiA 301 class
    (SENSOR_TIMEOUT: RPDO timeout) and the fault code in DETAIL; ERROR_CODE 0 after RESET."""
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    assert controller_emcy(loop, bus)[0] == 0
    bus.silent.add(0)
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault + 5)
    count, emcy = controller_emcy(loop, bus)
    assert ctl.state is State.FAULT and count == 1             # once per latch, not per cycle
    assert emcy["ERROR_CODE"] == EmcyCode.RPDO_TIMEOUT and emcy["DETAIL"] == Fault.SENSOR_TIMEOUT
    assert emcy["STATE"] == State.FAULT and emcy["ERROR_REGISTER"] == 1 and emcy["INFO"] == 1     # leg 1
    bus.silent.clear()
    cycles(loop, 2)
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED
    cycles(loop, 2)
    count, emcy = controller_emcy(loop, bus)
    assert count == 2 and emcy["ERROR_CODE"] == 0 and emcy["DETAIL"] == 0 and emcy["STATE"] == State.IDLE


@pytest.mark.parametrize("node, fault", [(1, Fault.VALVE_FAULT), (IMU_NODE, Fault.SENSOR_FAULT)])
def test_an_emcy_faults_the_controller_named_by_its_source(node, fault):
    loop, ctl, bus = make_loop("hexapod", "pi")
    cycles(loop, 20)
    message = load_database().get_message_by_name(f"EMCY_{node}")
    data = message.encode({"ERROR_CODE": 0x6000, "ERROR_REGISTER": 1, "STATE": 0, "DETAIL": 1, "SYNC_COUNTER": 0,
                           "INFO": 0})
    bus.queue.append(can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False))
    cycles(loop, 2)
    assert ctl.state is State.FAULT and ctl.sup.fault_code is fault
    assert loop.stats.faults == 1                              # the daemon's summary counts it


def test_testbench_waypoints_run_and_bad_ones_are_rejected():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 10)
    start = bus.y[0]
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.5) is Ack.OUTSIDE_WORKSPACE       # beyond the stroke
    assert send_waypoint(ctl, 1, 0.01, 0.0, 0.16) is Ack.OUTSIDE_WORKSPACE     # X must be 0
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.30, segment=0.2, accel=0.05) is Ack.TOO_FAST
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.16, segment=0.2, accel=0.15) is Ack.BAD_ARGUMENT
    assert send_waypoint(ctl, 1, 0.0, 0.0, math.nan) is Ack.NOT_FINITE
    ctl.waypoints.stage_position(2, 0.0, 0.0, 0.16)
    assert ctl.waypoint_commit(2, 2, 1.0, 0.2, 0) is Ack.INCOMPLETE                 # no ROT frame
    cycles(loop, 200)
    assert abs(bus.y[0] - start) < 0.3e-3                                          # nothing moved
    assert send_waypoint(ctl, 5, 0.0, 0.0, 0.16) is Ack.ACCEPTED
    assert send_waypoint(ctl, 7, 0.0, 0.0, 0.15) is Ack.SEQUENCE_GAP
    assert send_waypoint(ctl, 6, 0.0, 0.0, 0.15, flags=1) is Ack.ACCEPTED
    assert ctl.host_command(Command.START, 0) is Ack.ACCEPTED
    assert ctl.state is State.RUNNING
    peak = 0.0
    for _ in range(1100):                                   # two 1 s segments
        loop.cycle()
        peak = max(peak, bus.y[0])
    assert ctl.state is State.READY and ctl.active_waypoint == 6
    assert peak > 0.159 and abs(bus.y[0] - 0.15) < 0.5e-3


def test_hexapod_waypoints_checked_against_workspace_singularity_and_speed():
    loop, ctl, bus = make_loop("hexapod", "model-based")
    cycles(loop, 10)
    start = list(bus.y)
    assert send_waypoint(ctl, 1, 0.0, 0.0, 1.2) is Ack.OUTSIDE_WORKSPACE
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.66, rpy=(0.0, 0.0, math.radians(90.0))) in (
        Ack.SINGULAR, Ack.OUTSIDE_WORKSPACE)
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.75, segment=0.1, accel=0.05) is Ack.TOO_FAST
    cycles(loop, 100)
    assert np.max(np.abs(np.array(bus.y) - start)) < 0.3e-3
    assert send_waypoint(ctl, 1, 0.02, 0.0, 0.60, flags=3) is Ack.ACCEPTED         # last + start now
    assert ctl.state is State.RUNNING
    cycles(loop, 700)
    assert ctl.state is State.READY, ctl.sup.fault_code.name
    # the legs reach the waypoint's strokes (IK) to a fraction of an encoder count ...
    lengths, _ = ik_batch(ctl.geometry, np.array([[0.02, 0.0, 0.60]]), np.array([[1.0, 0.0, 0.0, 0.0]]))
    assert np.max(np.abs(np.array(bus.y) - (lengths[0] - ctl.geometry.leg_min_m))) < 0.1e-3
    # ... while the controller's DK of the quantised strokes is only as good as one count
    # (0.125 mm) through the slender legs (1 mm of leg = 7-10 mm horizontally): it hunts
    # between x = 18.4 and 20.4 mm as the counts flip
    assert np.allclose(ctl.platform.dk.pose[:3], [0.02, 0.0, 0.60], atol=2.5e-3)


def test_home_and_park_move_and_park_ends_idle():
    loop, ctl, bus = make_loop("testbench", "adaptive")
    assert ctl.host_command(Command.PARK, 0) is Ack.ACCEPTED
    cycles(loop, 4000)
    assert ctl.state is State.IDLE and abs(bus.y[0] - ctl.cfg.testbench.park_m) < 0.5e-3
    assert ctl.host_command(Command.HOME, 0) is Ack.ACCEPTED
    cycles(loop, 4000)
    assert ctl.state is State.READY and abs(bus.y[0] - ctl.cfg.testbench.home_m) < 0.5e-3


def test_a_silent_node_heartbeat_faults():
    loop, ctl, bus = make_loop("testbench", "pi", {"timing": {"heartbeat_timeout_ms": 10.0}})
    bus.nodes = []                                    # the node stops its heartbeat ...
    bus._hb.clear()
    time.sleep(0.05)
    loop.cycle()                                      # ... and the next cycle notices
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.HEARTBEAT_LOST


HOST_OUTBOXES = {}        # one per message, as on the host: the E2E counters advance per frame


def _host_frame(name, values):
    from copy import deepcopy

    from protocol.outbox import Outbox
    box = HOST_OUTBOXES.setdefault(name, Outbox(name))
    for key, value in values.items():
        box.values[box.index[key]] = value
    assert box.encode()
    return deepcopy(box.message)


def host_frames(seq, z, flags=0):
    """The three frames of a test-bench waypoint, encoded as the host sends them."""
    tag = seq & 0x0F
    return [_host_frame("HOST_WAYPOINT_POS", {"TAG": tag, "X": 0.0, "Y": 0.0, "Z": z}),
            _host_frame("HOST_WAYPOINT_ROT", {"TAG": tag, "ROLL": 0.0, "PITCH": 0.0, "YAW": 0.0}),
            _host_frame("HOST_WAYPOINT_TIME", {"TAG": tag, "SEQ": seq, "SEGMENT_TIME": 1.0, "ACCEL_TIME": 0.2,
                                               "FLAGS": flags})]


def host_command_frame(command, seq):
    return _host_frame("HOST_CMD", {"COMMAND": int(command), "ARGUMENT": 0, "SEQ": seq})


def test_a_commit_waits_for_a_cycle_with_room_before_the_next_sync_but_not_forever():
    loop, ctl, bus = make_loop("testbench", "pi")
    z = ctl.reference.hold_position[0]
    for frame in host_frames(0, z + 0.01):
        loop.dispatch(frame)
    ctl.host.run_before_update(ctl)
    tight = 0.5 * ctl.cfg.timing.commit_room_s
    for _ in range(COMMIT_MAX_WAIT_CYCLES):
        ctl.after_write(tight)                       # the SYNC is near: the commit waits
    assert not ctl.host.acks and len(ctl.host.queue) == 1
    ctl.after_write(tight)                           # waited its longest: it runs anyway
    assert list(ctl.host.acks) == [(AckKind.WAYPOINT, 0, int(Ack.ACCEPTED))] and ctl.host.commit_waited == 0
    for frame in host_frames(1, z + 0.02, flags=1):
        loop.dispatch(frame)
    ctl.host.run_before_update(ctl)
    ctl.after_write(tight)
    assert len(ctl.host.acks) == 1
    ctl.after_write(ctl.cfg.timing.commit_room_s)           # room enough: at once
    assert list(ctl.host.acks)[-1] == (AckKind.WAYPOINT, 1, int(Ack.ACCEPTED))


def test_waypoint_commits_wait_for_the_host_work_slot_and_estop_does_not():
    loop, ctl, bus = make_loop("testbench", "pi")
    z = ctl.reference.hold_position[0]
    for frame in host_frames(0, z + 0.01) + host_frames(1, z + 0.02, flags=1):
        loop.dispatch(frame)                         # as if received inside the sensor window
    loop.dispatch(host_command_frame(Command.START, 1))
    assert not ctl.host.acks and len(ctl.waypoints.queue) == 0   # only queued: the cycle goes first
    ctl.host.run_before_update(ctl)                  # in the update: the halves, not the commit
    assert not ctl.host.acks and len(ctl.waypoints.queue) == 0
    ctl.after_write()                                # one commit per cycle, after the write
    assert list(ctl.host.acks) == [(AckKind.WAYPOINT, 0, int(Ack.ACCEPTED))] and len(ctl.waypoints.queue) == 1
    loop.dispatch(host_command_frame(Command.ESTOP, 2))
    ctl.host.run_before_update(ctl)
    assert ctl.state is State.ESTOP                  # never waits behind a commit
    ctl.after_write()                                # the second commit ...
    ctl.host.run_before_update(ctl)                  # ... then START, in order
    acks = list(ctl.host.acks)
    assert [a[:2] for a in acks] == [(AckKind.WAYPOINT, 0), (AckKind.HOST_CMD, 2), (AckKind.WAYPOINT, 1),
                                     (AckKind.HOST_CMD, 1)]
    assert acks[2][2] == int(Ack.BAD_STATE) and not ctl.host.queue    # after the E-stop


def test_a_lost_heartbeat_faults_before_the_cycle_writes():
    """The supervisor sees a lost heartbeat in the cycle that reads it: that cycle's VALVE_CMD
    already holds the valves."""
    loop, ctl, bus = make_loop("testbench", "pi", {"timing": {"heartbeat_timeout_ms": 10.0}})
    cycles(loop, 5)
    bus.nodes = []
    bus._hb.clear()
    time.sleep(0.05)
    loop.cycle()
    assert ctl.sup.fault_code is Fault.HEARTBEAT_LOST
    assert valve_words(loop)[2] == 0                 # M = 0 in the very cycle


def test_enable_while_ready_is_a_harmless_repeat():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 5)
    held = ctl.reference.hold_position.copy()
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    assert ctl.state is State.READY and np.array_equal(ctl.reference.hold_position, held)


def test_reset_and_enable_at_the_end_stop_comes_back_inside_the_guard():
    """After a POSITION_LIMIT at the end stop, RESET + ENABLE holds just inside the guard and
    brings the leg back; it does not re-fault at once (the only way off the stop)."""
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    bus.y[0] = ctl.stroke_m - 0.4e-3                      # the piston rests on its top stop
    cycles(loop, 3)
    assert ctl.sup.fault_code is Fault.POSITION_LIMIT
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED
    cycles(loop, 5)
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    assert ctl.limits.recovering[0] and ctl.reference.hold_position[0] < ctl.stroke_m - ctl.cfg.limits.stroke_margin_m
    cycles(loop, 400)
    assert ctl.state is State.READY and ctl.sup.fault_code is Fault.NONE
    assert bus.y[0] < ctl.stroke_m - ctl.cfg.limits.stroke_margin_m and not ctl.limits.recovering[0]


def test_a_recovering_leg_that_goes_further_out_faults():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    bus.y[0] = ctl.stroke_m - 0.6e-3
    cycles(loop, 3)
    ctl.host_command(Command.RESET, 0)
    cycles(loop, 5)
    ctl.host_command(Command.ENABLE, 0)
    bus.y[0] = ctl.stroke_m - 0.05e-3                     # pushed on, past the slack
    cycles(loop, 2)
    assert ctl.sup.fault_code is Fault.POSITION_LIMIT


def test_plausibility_window_needs_motion_along_the_command():
    from firmware_py.supervision.plausibility import MotionPlausibility
    check = MotionPlausibility(2, input_min_v=2.0, window=10, travel_min_m=1e-3)
    spool, y = np.array([3.0, -3.0]), np.zeros(2)
    for _ in range(9):                                   # leg 1 follows, leg 2 does not
        y[0] += 0.5e-3
        assert not check.update(spool, y)
    y[0] += 0.5e-3
    assert check.update(spool, y)                        # the 10th cycle closes leg 2's window
    check.reset()
    for _ in range(30):                                  # both move their way: never
        y += np.array([0.2e-3, -0.2e-3])
        assert not check.update(spool, y)
    for k in range(30):                                  # a command that flips every 5 cycles
        assert not check.update(spool * (1 if k // 5 % 2 else -1), y)
    for _ in range(30):                                  # below the threshold: not judged
        assert not check.update(np.array([1.9, -1.9]), y)


def test_plausibility_counts_progress_from_the_furthest_point_back():
    """A heavy load still coasting against a reversed command, then following it, is
    plausible (sha-identification's P-control reversals with 6 kg); coasting, then still, is not."""
    from firmware_py.supervision.plausibility import MotionPlausibility
    check = MotionPlausibility(2, input_min_v=0.5, window=25, travel_min_m=0.5e-3)
    spool, y = np.array([1.0, 1.0]), np.zeros(2)
    for k in range(25):
        y -= 0.2e-3 if k < 12 else 0.0                  # both coast back 2.4 mm for 12 cycles
        y[0] += 0.3e-3 if k >= 12 else 0.0               # then leg 1 comes forward 3.9 mm: net -1.5 mm
        tripped = check.update(spool, y)
    assert tripped                                       # leg 2 never came forward
    check.reset()
    y[:] = 0.0
    for k in range(25):                                  # leg 1 alone now: the same motion
        y[0] += -0.2e-3 if k < 12 else 0.3e-3
        assert not check.update(np.array([1.0, 0.0]), y)


def test_a_stuck_encoder_during_a_move_faults_within_half_a_second():
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.20, segment=1.0, accel=0.2, flags=3) is Ack.ACCEPTED
    cycles(loop, 200)
    assert ctl.state is State.RUNNING
    bus.stuck[0] = round(bus.y[0] / bus.res) * bus.res
    k = cycles_until_fault(loop, 1000)
    # the actuator's residual (its chamber model sees the valve drive a leg that does not move),
    # the test bench's plausibility window (5 % for 50 ms, [testbench]) or the 25 mm tracking
    # limit, whichever first (the PI drives a leg it cannot see)
    assert ctl.sup.fault_code in (Fault.ACTUATOR_RESIDUAL, Fault.MOTION_PLAUSIBILITY, Fault.TRACKING_ERROR), \
        ctl.sup.fault_code.name
    assert k <= 250


@given(roll=st.floats(-3.1, 3.1), pitch=st.floats(-1.5, 1.5), yaw=st.floats(-3.1, 3.1),
       axis=st.tuples(*[st.floats(-1, 1)] * 3), angle=st.floats(0.0, 3.1))
@settings(max_examples=200, deadline=None)
def test_attitude_kernels_match_scipy(roll, pitch, yaw, axis, angle):
    from scipy.spatial.transform import Rotation

    from firmware_py.mechanics.rotation import angle_between_matrices, rpy_to_matrix_into
    rot = np.empty((3, 3))
    rpy_to_matrix_into(roll, pitch, yaw, rot)
    oracle = Rotation.from_euler("ZYX", [yaw, pitch, roll])          # R = Rz Ry Rx, the bus's convention
    np.testing.assert_allclose(rot, oracle.as_matrix(), atol=1e-12)
    axis = np.asarray(axis)
    assume(np.linalg.norm(axis) > 0.1)
    turned = oracle * Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle)
    assert angle_between_matrices(rot, turned.as_matrix()) == pytest.approx(angle, abs=1e-6)


def test_attitude_cross_check_needs_samples_in_a_row():
    from firmware_py.supervision.plausibility import AttitudeCrossCheck
    check = AttitudeCrossCheck(limit_rad=math.radians(1.0), samples=3)
    level = np.eye(3)
    assert not check.update(level, 0.0, 0.0, 0.0) and check.angle_rad < 1e-12
    assert not check.update(level, 0.02, 0.0, 0.0)                # 1.15 deg: 1 of 3
    assert not check.update(level, 0.0, 0.0, 0.0)                 # agreement starts over
    assert not check.update(level, 0.0, -0.02, 0.0)
    assert not check.update(level, 0.0, 0.0, 0.02)
    assert check.update(level, 0.015, 0.015, 0.0)                 # the third in a row
    assert check.angle_rad == pytest.approx(math.hypot(0.015, 0.015), rel=1e-3)
    assert check.ratio == pytest.approx(check.angle_rad / math.radians(1.0))


def test_a_frozen_hexapod_encoder_is_caught_by_the_imu():
    """A leg's encoder freezes while the leg moves on: the encoders' attitude leaves the IMU's."""
    loop, ctl, bus = make_loop("hexapod", "pi")
    bus.imu_rpy = [0.0, 0.0, 0.0]
    cycles(loop, 50)
    assert ctl.state is State.READY and ctl.attitude_check.angle_rad < 2e-3
    # leg 1's encoder freezes; the leg itself is 10 mm further out, which the IMU sees
    bus.stuck[0] = round(bus.y[0] / bus.res) * bus.res
    lengths = np.asarray(bus.y) + ctl.geometry.leg_min_m
    lengths[0] += 0.010
    dk = DirectKinematics(ctl.geometry, 1e-9, 50)
    dk.solve(lengths)
    assert dk.converged
    bus.imu_rpy = list(quat_to_rpy(dk.pose[3:7]))
    k = cycles_until_fault(loop, 10)
    assert ctl.sup.fault_code is Fault.ATTITUDE_MISMATCH, ctl.sup.fault_code.name
    assert k == 3                                                 # the third IMU frame in a row
    assert valve_words(loop)[2] == 0


def test_a_stalled_realtime_loop_faults_overrun_and_stays_held_until_reset():
    loop, ctl, bus = make_loop("testbench", "pi")
    now = [0.0]
    loop.clock = lambda: now[0]
    loop._stall_s = ctl.cfg.timing.stall_fault_periods * loop.period_s        # as in realtime pacing
    for _ in range(20):
        now[0] += loop.period_s
        loop.cycle()
    assert ctl.state is State.READY
    now[0] += 0.050                                                     # SIGSTOP for 50 ms
    loop.cycle()
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.OVERRUN
    assert loop.stats.faults == 1                              # the stall's fault is counted too
    for _ in range(100):
        now[0] += loop.period_s
        loop.cycle()
        assert valve_words(loop)[2] == 0                           # M = 0: held, no motion
    assert ctl.state is State.FAULT
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED
    loop.cycle()                                          # every sensor reported: estimators restart
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    for _ in range(10):
        now[0] += loop.period_s
        loop.cycle()
    assert ctl.state is State.READY


def test_nodes_that_reboot_are_started_again_on_reset():
    import can
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    bus.silent.add(0)                                     # the node powers down ...
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault)
    assert ctl.sup.fault_code is Fault.SENSOR_TIMEOUT
    bus.operational = False                               # ... and boots again, PRE-OPERATIONAL
    bus.valve[0] = 1
    bus.silent.clear()
    for state in (0, 127):
        bus.queue.append(can.Message(arbitration_id=0x701, data=bytearray([state]), is_extended_id=False))
    cycles(loop, 3)
    assert loop.nmt_state[1] == 127
    starts = bus.sent[0x000]
    ctl.host.command(int(Command.RESET), 0, 1)
    loop.cycle()
    assert bus.sent[0x000] == starts + 1 and bus.operational     # NMT start sent with the RESET's ack
    cycles(loop, 10)
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.state is State.READY and bus.valve == [3]


def test_after_reset_enable_waits_for_every_sensor_and_holds_where_it_reads():
    """A sensor node silent, RESET, the node back reading 30 mm elsewhere (restarted, or the
    rod moved while unseen): ENABLE is refused until it has reported, then the estimators
    start there and the leg is held where it is, not driven to where it was last seen."""
    loop, ctl, bus = make_loop("testbench", "pi")
    cycles(loop, 20)
    assert ctl.state is State.READY
    bus.silent.add(0)
    cycles(loop, 10)
    assert ctl.state is State.FAULT and ctl.sup.fault_code is Fault.SENSOR_TIMEOUT
    bus.y[0] += 0.030
    assert ctl.host_command(Command.RESET, 0) is Ack.ACCEPTED and ctl.state is State.IDLE
    cycles(loop, 2)
    assert ctl.host_command(Command.ENABLE, 0) is Ack.BAD_STATE       # still silent
    bus.silent.discard(0)
    cycles(loop, 1)
    assert ctl.host_command(Command.ENABLE, 0) is Ack.ACCEPTED
    cycles(loop, 100)
    assert ctl.state is State.READY, ctl.sup.fault_code.name
    assert abs(ctl.reference.yr[0] - bus.y[0]) < 1e-3 and abs(loop.meas.position_m[0] - bus.y[0]) < 1e-3
