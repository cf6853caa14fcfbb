"""The host's frames on their way into the controller (hostlink.py): in arrival order, the
commands and waypoint halves in the update, one waypoint commit per cycle after the write
when the cycle has room, ESTOP and DISABLE never waiting."""

from copy import deepcopy

from firmware_py.hostlink import COMMIT_MAX_WAIT_CYCLES
from protocol.enums import Ack, AckKind, Command, State
from protocol.outbox import Outbox
from tests.support.loops import bus_loop

HOST_OUTBOXES = {}        # one per message, as on the host: the E2E counters advance per frame


def _host_frame(name, values):
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
    HOST_OUTBOXES.clear()
    loop, ctl, bus = bus_loop("testbench", "pi")
    z = float(ctl.status.hold_m[0])
    for frame in host_frames(0, z + 0.01):
        loop.dispatch(frame)
    ctl.host.run_before_update(ctl)
    tight = 0.5 * ctl.cfg.timing.commit_room_s
    for _ in range(COMMIT_MAX_WAIT_CYCLES):
        ctl.after_write(tight)                       # the SYNC is near: the commit waits
    assert not ctl.host.acks and len(ctl.host.queue) == 1
    ctl.meas.overrun = True
    ctl.after_write(tight)                           # waited its longest, but the last cycle overran
    assert not ctl.host.acks
    ctl.meas.overrun = False
    ctl.after_write(tight)                           # waited its longest: it runs anyway
    assert list(ctl.host.acks) == [(AckKind.WAYPOINT, 0, int(Ack.ACCEPTED), 0.0)] and ctl.host.commit_waited == 0
    for frame in host_frames(1, z + 0.02, flags=1):
        loop.dispatch(frame)
    ctl.host.run_before_update(ctl)
    ctl.after_write(tight)
    assert len(ctl.host.acks) == 1
    ctl.after_write(ctl.cfg.timing.commit_room_s)           # room enough: at once
    assert list(ctl.host.acks)[-1] == (AckKind.WAYPOINT, 1, int(Ack.ACCEPTED), 0.0)


def test_waypoint_commits_wait_for_the_host_work_slot_and_estop_does_not():
    HOST_OUTBOXES.clear()
    loop, ctl, bus = bus_loop("testbench", "pi")
    z = float(ctl.status.hold_m[0])
    queue_free = ctl.status.queue_free
    for frame in host_frames(0, z + 0.01) + host_frames(1, z + 0.02, flags=1):
        loop.dispatch(frame)                         # as if received inside the sensor window
    loop.dispatch(host_command_frame(Command.START, 1))
    assert not ctl.host.acks and ctl.status.queue_free == queue_free    # only queued: the cycle goes first
    ctl.host.run_before_update(ctl)                  # in the update: the halves, not the commit
    assert not ctl.host.acks and ctl.status.queue_free == queue_free
    ctl.after_write()                                # one commit per cycle, after the write
    assert list(ctl.host.acks) == [(AckKind.WAYPOINT, 0, int(Ack.ACCEPTED), 0.0)]
    assert ctl.status.queue_free == queue_free - 1
    loop.dispatch(host_command_frame(Command.ESTOP, 2))
    ctl.host.run_before_update(ctl)
    assert ctl.status.state is State.ESTOP           # never waits behind a commit
    ctl.after_write()                                # the second commit ...
    ctl.host.run_before_update(ctl)                  # ... then START, in order
    acks = list(ctl.host.acks)
    assert [a[:2] for a in acks] == [(AckKind.WAYPOINT, 0), (AckKind.HOST_CMD, 2), (AckKind.WAYPOINT, 1),
                                     (AckKind.HOST_CMD, 1)]
    assert acks[2][2] == int(Ack.BAD_STATE) and not ctl.host.queue    # after the E-stop


class SpendingClock:
    """Each reading is `step_s` later: a stage of the check costs one reading."""

    def __init__(self, step_s):
        self.now, self.step_s = 0.0, step_s

    def __call__(self):
        self.now += self.step_s
        return self.now


def _hexapod_commit(ctl, seq, position, segment=1.0, accel=0.2, flags=3):
    ctl.host.waypoint_position(seq & 0x0F, *position)
    ctl.host.waypoint_rotation(seq & 0x0F, 0.0, 0.0, 0.0)
    ctl.host.waypoint_commit(seq & 0x0F, seq, segment, accel, flags)
    ctl.host.run_before_update(ctl)


def test_a_hexapod_commit_is_checked_in_stages_over_the_cycles_slack_with_the_same_verdict():
    """~2 ms of checks run a stage at a time while the cycle has commit_room left: the ack
    comes cycles later, and the waypoint queued is the one a commit at once queues."""
    at_once_loop, at_once, _ = bus_loop("hexapod", "computed-torque")
    staged_loop, staged, _ = bus_loop("hexapod", "computed-torque")
    target = (0.02, -0.01, 0.60)
    for ctl in (at_once, staged):
        _hexapod_commit(ctl, 1, target, flags=0)
    at_once.after_write()
    room = staged.cfg.timing.commit_room_s
    clock, calls = SpendingClock(0.5 * room), 0
    while not staged.host.acks:
        staged.after_write(1.6 * room, clock)       # room for two stages a cycle
        calls += 1
    assert calls >= 4 and staged.host.acks[-1] == at_once.host.acks[-1] == (AckKind.WAYPOINT, 1, int(Ack.ACCEPTED),
                                                                            0.0)
    assert (staged.waypoints.queue[-1].strokes == at_once.waypoints.queue[-1].strokes).all()


def test_a_staged_commit_starts_again_when_the_queue_changes_under_it_and_yields_to_an_estop():
    loop, ctl, _ = bus_loop("hexapod", "computed-torque")
    _hexapod_commit(ctl, 1, (0.02, -0.01, 0.60), flags=0)
    _hexapod_commit(ctl, 2, (0.0, 0.02, 0.62), flags=0)
    ctl.after_write()                                # the first: queued
    ctl.host.run_before_update(ctl)                  # the next update: the second's halves
    room = ctl.cfg.timing.commit_room_s
    ctl.after_write(1.6 * room, SpendingClock(0.5 * room))    # the second: two stages of it
    assert len(ctl.host.acks) == 1 and len(ctl.waypoints.queue) == 1
    ctl.waypoints.clear()                            # (as CLEAR_WAYPOINTS would, were it not behind it)
    ctl.after_write()
    # checked again from the empty queue, where SEQ 2 is the first after the clear: accepted alone
    assert ctl.host.acks[-1][:3] == (AckKind.WAYPOINT, 2, int(Ack.ACCEPTED))
    assert [w.seq for w in ctl.waypoints.queue] == [2] and (ctl.waypoints.queue[0].start == ctl.reference.yr).all()
    _hexapod_commit(ctl, 3, (0.02, -0.01, 0.60), flags=0)
    ctl.after_write(1.6 * room, SpendingClock(0.5 * room))
    loop.dispatch(host_command_frame(Command.ESTOP, 5))
    ctl.host.run_before_update(ctl)                  # ESTOP never waits behind it ...
    assert ctl.status.state is State.ESTOP
    ctl.after_write()                                # ... and the commit it interrupted is refused
    assert ctl.host.acks[-1][:3] == (AckKind.WAYPOINT, 3, int(Ack.BAD_STATE))
