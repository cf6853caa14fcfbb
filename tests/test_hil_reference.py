"""The reference the HIL analysis rebuilds from a log equals the controller core's own,
cycle by cycle: a move started at once, a step queued to start when it ends, then a
multi-point trajectory queued the same way (the rules of firmware_py/core.py)."""

import numpy as np

from firmware_py.supervisor import Ack
from hil.logdata import Event, LogData, Series
from hil.reference import rebuild
from protocol.values import FLAG_LAST, FLAG_START, FLAG_STEP, KIND_WAYPOINT
from tests.test_controller_alloc import make_loop


def _events(cycle, seq, z, segment, accel, flags, result):
    return [Event(cycle, 0.0, "HOST_WAYPOINT_POS", {"TAG": seq & 15, "X": 0.0, "Y": 0.0, "Z": z}),
            Event(cycle, 0.0, "HOST_WAYPOINT_ROT", {"TAG": seq & 15, "ROLL": 0.0, "PITCH": 0.0, "YAW": 0.0}),
            Event(cycle, 0.0, "HOST_WAYPOINT_TIME", {"TAG": seq & 15, "SEQ": seq, "SEGMENT_TIME": segment,
                                                     "ACCEL_TIME": accel, "FLAGS": flags}),
            Event(cycle, 0.0, "CTRL_ACK", {"KIND": KIND_WAYPOINT, "SEQ": seq, "RESULT": int(result), "QUEUE_FREE": 0})]


def test_rebuilt_reference_equals_the_cores():
    loop, core, bus = make_loop("testbench", "pi")
    period = loop.period_s
    plan = {                 # cycle -> waypoints sent before that cycle's update (seq, z, segment, accel, flags)
        20: [(0, 0.160, 0.001 * 500, 0.001 * 100, FLAG_LAST | FLAG_START)],
        120: [(1, 0.170, 0.001 * 300, 0.001 * 150, FLAG_LAST | FLAG_START | FLAG_STEP)],
        130: [(2, 0.180, 0.001 * 250, 0.001 * 50, FLAG_START), (3, 0.150, 0.001 * 370, 0.001 * 100, FLAG_LAST)],
    }
    events, yr, initial = [], [], None
    for cycle in range(900):
        for seq, z, segment, accel, flags in plan.get(cycle, []):
            if initial is None:
                initial = core.yr.copy()
            core.waypoint_position(seq & 15, 0.0, 0.0, z)
            core.waypoint_rotation(seq & 15, 0.0, 0.0, 0.0)
            result = core.waypoint_time(seq & 15, seq, segment, accel, flags)
            assert result is Ack.ACCEPTED
            events += _events(cycle, seq, z, segment, accel, flags, result)
        loop.cycle()
        yr.append(core.yr[0])
    n = len(yr)
    log = LogData("synthetic", n, np.zeros(n), {"LEG_STATE_1": Series(
        "LEG_STATE_1", np.arange(n), np.zeros(n), np.full((n, 6), 0.15), {"POSITION": 4})}, events, 0, {}, {}, 0)
    ref = rebuild(log, "testbench", period, initial_position=initial)
    assert [m.seqs for m in ref.motions] == [[0], [1], [2, 3]]
    assert ref.motions[1].step
    rebuilt = ref.yr[20:, 0]
    assert np.isfinite(rebuilt).all()
    np.testing.assert_array_equal(rebuilt, np.array(yr[20:]))
