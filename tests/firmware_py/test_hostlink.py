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
