"""Waypoints (waypoints.py): each one checked before use with a reason code (a rejected one
never moves anything), the accepted ones run; on the test bench and the hexapod, through the
real loop on the emulated rig."""

import math

import numpy as np

from firmware_py.mechanics.kinematics import ik_batch
from protocol.enums import Ack, Command, State
from tests.support.loops import bus_loop, command, cycles, send_waypoint


def test_testbench_waypoints_run_and_bad_ones_are_rejected():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 10)
    stroke = bus.sim.rig.stroke_m
    start = float(stroke[0])
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.5) is Ack.OUTSIDE_WORKSPACE       # beyond the stroke
    assert send_waypoint(ctl, 1, 0.01, 0.0, 0.16) is Ack.OUTSIDE_WORKSPACE     # X must be 0
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.30, segment=0.2, accel=0.05) is Ack.TOO_FAST
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.16, segment=0.2, accel=0.15) is Ack.BAD_ARGUMENT
    assert send_waypoint(ctl, 1, 0.0, 0.0, math.nan) is Ack.NOT_FINITE
    ctl.host.waypoint_position(2, 0.0, 0.0, 0.16)                              # no ROT frame
    ctl.host.waypoint_commit(2, 2, 1.0, 0.2, 0)
    ctl.host.run_before_update(ctl)
    ctl.after_write()
    assert ctl.host.acks[-1][2] == Ack.INCOMPLETE
    cycles(loop, 200)
    assert abs(stroke[0] - start) < 0.3e-3                                     # nothing moved
    assert send_waypoint(ctl, 5, 0.0, 0.0, 0.16) is Ack.ACCEPTED
    assert send_waypoint(ctl, 7, 0.0, 0.0, 0.15) is Ack.SEQUENCE_GAP
    assert send_waypoint(ctl, 6, 0.0, 0.0, 0.15, flags=1) is Ack.ACCEPTED
    assert command(ctl, Command.START) is Ack.ACCEPTED
    assert ctl.status.state is State.RUNNING
    peak = 0.0
    for _ in range(1100):                                   # two 1 s segments
        loop.cycle()
        peak = max(peak, float(stroke[0]))
    assert ctl.status.state is State.READY and ctl.status.active_waypoint == 6
    assert peak > 0.159 and abs(stroke[0] - 0.15) < 0.5e-3


def test_hexapod_waypoints_checked_against_workspace_singularity_and_speed():
    loop, ctl, bus = bus_loop("hexapod", "model-based")
    cycles(loop, 10)
    stroke = bus.sim.rig.stroke_m
    start = stroke.copy()
    assert send_waypoint(ctl, 1, 0.0, 0.0, 1.2) is Ack.OUTSIDE_WORKSPACE
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.66, rpy=(0.0, 0.0, math.radians(90.0))) in (
        Ack.SINGULAR, Ack.OUTSIDE_WORKSPACE)
    assert send_waypoint(ctl, 1, 0.0, 0.0, 0.75, segment=0.1, accel=0.05) is Ack.TOO_FAST
    cycles(loop, 100)
    assert np.max(np.abs(stroke - start)) < 0.3e-3
    assert send_waypoint(ctl, 1, 0.02, 0.0, 0.60, flags=3) is Ack.ACCEPTED         # last + start now
    assert ctl.status.state is State.RUNNING
    cycles(loop, 700)
    assert ctl.status.state is State.READY, ctl.status.fault.name
    # the legs reach the waypoint's strokes (IK) to about two encoder counts (PI on legs under load) ...
    geometry = ctl.rig.geometry
    lengths, _ = ik_batch(geometry, np.array([[0.02, 0.0, 0.60]]), np.array([[1.0, 0.0, 0.0, 0.0]]))
    assert np.max(np.abs(stroke - (lengths[0] - geometry.leg_min_m))) < 0.3e-3
    # ... and the platform is there (the emulator's truth); the controller's DK of the
    # quantised strokes is only as good as one count (0.125 mm) through the slender legs
    # (1 mm of leg = 7-10 mm horizontally): it hunts as the counts flip
    truth, _ = bus.sim.rig.platform_pose()
    assert np.allclose(truth, [0.02, 0.0, 0.60], atol=2e-3)
    assert np.allclose(ctl.status.pose[:3], [0.02, 0.0, 0.60], atol=3e-3)
