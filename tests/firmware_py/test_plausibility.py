"""Plausibility of the measurements (plausibility.py): a valve driven hard must move its leg
(the motion window), the encoders' attitude must agree with the IMU's; each as a unit, and a
frozen encoder caught by them through the real loop on the emulated rig."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from firmware_py.config import load_config
from firmware_py.supervision.capacity import leg_capacity
from firmware_py.supervision.plausibility import AttitudeCrossCheck, MotionPlausibility
from protocol.enums import Ack, EmuFault, Fault, State
from tests.support.loops import bus_loop, cycles, cycles_until_fault, inject, send_waypoint, valve_words

CAPACITY = leg_capacity(load_config())


def window(n: int, spool_min: float, cycles: int, travel_m: float):
    """A motion window, and its update with the load cells and velocities at rest (no load)."""
    check = MotionPlausibility(n, spool_min, cycles, travel_m, CAPACITY, 0.9)
    rest = np.zeros(n)
    return check, lambda spool, y: check.update(spool, y, rest, rest)


def test_plausibility_window_needs_motion_along_the_command():
    check, update = window(2, spool_min=0.2, cycles=10, travel_m=1e-3)
    spool, y = np.array([0.3, -0.3]), np.zeros(2)
    for _ in range(9):                                   # leg 1 follows, leg 2 does not
        y[0] += 0.5e-3
        assert not update(spool, y)
    y[0] += 0.5e-3
    assert update(spool, y)                              # the 10th cycle closes leg 2's window
    check.reset()
    for _ in range(30):                                  # both move their way: never
        y += np.array([0.2e-3, -0.2e-3])
        assert not update(spool, y)
    for k in range(30):                                  # a command that flips every 5 cycles
        assert not update(spool * (1 if k // 5 % 2 else -1), y)
    for _ in range(30):                                  # below the threshold: not judged
        assert not update(np.array([0.19, -0.19]), y)


def test_plausibility_counts_progress_from_the_furthest_point_back():
    """A heavy load still coasting against a reversed command, then following it, is
    plausible (sha-identification's P-control reversals with 6 kg); coasting, then still, is not."""
    check, update = window(2, spool_min=0.05, cycles=25, travel_m=0.5e-3)
    spool, y = np.array([0.1, 0.1]), np.zeros(2)
    for k in range(25):
        y -= 0.2e-3 if k < 12 else 0.0                  # both coast back 2.4 mm for 12 cycles
        y[0] += 0.3e-3 if k >= 12 else 0.0               # then leg 1 comes forward 3.9 mm: net -1.5 mm
        tripped = update(spool, y)
    assert tripped                                       # leg 2 never came forward
    check.reset()
    y[:] = 0.0
    for k in range(25):                                  # leg 1 alone now: the same motion
        y[0] += -0.2e-3 if k < 12 else 0.3e-3
        assert not update(np.array([0.1, 0.0]), y)


def test_a_leg_held_back_at_its_limit_is_not_a_leg_that_cannot_move():
    """A payload's corner: a leg pulling at its limit while its load carries it through its
    reversal, the command beyond the threshold for the whole window. At the force its valve
    gives it is held back by its load and its window starts again; the same motion with the
    load cell at half of it (a supply lost, a seized rod) is implausible."""
    push, pull = (float(limit[0]) for limit in CAPACITY.limits(np.zeros(1)))
    for share, tripped in ((1.0, False), (0.5, True)):
        check = MotionPlausibility(1, 0.3, 100, 0.5e-3, CAPACITY, 0.9)
        y, velocity = np.zeros(1), np.zeros(1)
        results = []
        for k in range(100):
            velocity[0] = -0.1 + 0.2 * k / 100                # -100 -> +100 mm/s through 0
            y += velocity * 0.002
            results.append(check.update(np.array([-0.75]), y, np.array([share * pull]), velocity))
        assert any(results) is tripped, share
    assert push > 0.0 > pull


def test_a_stuck_encoder_during_a_move_faults_within_half_a_second():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.20, segment=1.0, accel=0.2, flags=3) is Ack.ACCEPTED
    cycles(loop, 200)
    assert ctl.status.state is State.RUNNING
    inject(bus, 1, EmuFault.STUCK)
    k = cycles_until_fault(loop, 1000)
    # the node's readings frozen: its load cell's (no noise left), the actuator's residual (its
    # chamber model sees the valve drive a leg that does not move), the motion window or the
    # 25 mm tracking limit, whichever first (the PI drives a leg it cannot see)
    assert ctl.status.fault in (Fault.LOAD_CELL, Fault.ACTUATOR_RESIDUAL, Fault.MOTION_PLAUSIBILITY,
                                Fault.TRACKING_ERROR), ctl.status.fault.name
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


def test_a_drifting_hexapod_encoder_is_caught_by_the_imu():
    """A leg's encoder drifts (20 mm/s) while the platform holds: the controller follows the
    wrong reading, the leg moves, and the encoders' attitude leaves the IMU's (the actuators'
    residuals off: the IMU is the witness here)."""
    loop, ctl, bus = bus_loop("hexapod", "pi", {"residuals": {"enabled": False}})
    cycles(loop, 50)
    assert ctl.status.state is State.READY and ctl.status.attitude_mismatch_rad < 5e-3
    inject(bus, 1, EmuFault.ENCODER_DRIFT, 20_000)
    k = cycles_until_fault(loop, 600)
    assert ctl.status.fault is Fault.ATTITUDE_MISMATCH, ctl.status.fault.name
    assert k < 600 and valve_words(loop)[2] == 0                  # the valves hold in that cycle
