"""A trajectory plays only once its LAST is queued, so a waypoint without LAST is judged as
the trajectory passes it, and its stop is judged with the LAST that ends it."""

import numpy as np

from protocol.enums import Ack, Command, State, WaypointFlag
from tests.support.loops import bus_loop, command, cycles, send_waypoint
from tests.support.queues import commit, waypoint_queue

START, LAST = int(WaypointFlag.START), int(WaypointFlag.LAST)
THROUGH = (0.1, 0.0, 0.631, 0.0, 0.0, 0.0)     # 100 mm sideways in 0.2 s: more than the legs stop from


def test_a_waypoint_passed_is_judged_without_its_stop():
    queue, model = waypoint_queue("hexapod")
    assert commit(queue, model, 0, THROUGH, 0.2, 0.05, flags=LAST) is Ack.BEYOND_CAPACITY
    queue, model = waypoint_queue("hexapod")
    assert commit(queue, model, 0, THROUGH, 0.2, 0.05, flags=0) is Ack.ACCEPTED
    # the stop is judged with the LAST: too short a one is refused, a gentle one accepted
    assert commit(queue, model, 1, (0.11, 0.0, 0.631, 0.0, 0.0, 0.0), 0.1, 0.05) is Ack.BEYOND_CAPACITY
    assert commit(queue, model, 1, (0.2, 0.0, 0.631, 0.0, 0.0, 0.0), 0.4, 0.2) is Ack.ACCEPTED


def test_the_queues_last_place_is_kept_for_a_last():
    queue, model = waypoint_queue("hexapod", {"waypoints": {"queue": 3}})
    for seq in range(2):
        assert commit(queue, model, seq, (0.01 * (seq + 1), 0.0, 0.631, 0.0, 0.0, 0.0), 1.0, 0.2, flags=0) \
            is Ack.ACCEPTED
    assert commit(queue, model, 2, (0.03, 0.0, 0.631, 0.0, 0.0, 0.0), 1.0, 0.2, flags=0) is Ack.QUEUE_FULL
    assert commit(queue, model, 2, (0.03, 0.0, 0.631, 0.0, 0.0, 0.0), 1.0, 0.2, flags=LAST) is Ack.ACCEPTED
    assert queue.take(model.home_strokes) is not None and not queue.queue


def test_a_trajectory_waits_for_its_last_then_starts():
    loop, ctl, bus = bus_loop("hexapod", "computed-torque")
    cycles(loop, 10)
    stroke = bus.sim.rig.stroke_m
    start = stroke.copy()
    assert send_waypoint(ctl, 1, 0.02, 0.0, 0.60, segment=0.6, accel=0.2, flags=START) is Ack.ACCEPTED
    assert command(ctl, Command.START) is Ack.INCOMPLETE
    cycles(loop, 200)
    assert ctl.status.state is State.READY
    assert np.max(np.abs(stroke - start)) < 0.3e-3                 # nothing moved: the trajectory is not complete
    assert send_waypoint(ctl, 2, 0.04, 0.0, 0.60, segment=0.6, accel=0.2, flags=LAST) is Ack.ACCEPTED
    assert ctl.status.state is State.RUNNING                        # its first waypoint's START: at once
    cycles(loop, 800)
    assert ctl.status.state is State.READY, ctl.status.fault.name
    assert ctl.status.active_waypoint == 2
