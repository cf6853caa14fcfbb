"""The host's frames on their way into the controller, in arrival order, each carried out at
its place in the cycle, and the acknowledgements going back.

The loop only queues what it decoded. The controller carries the queue out:
- in its update, before the reference is computed: the frames at the front up to the first
  waypoint commit (commands, waypoint halves, tests), and ESTOP and DISABLE wherever they
  stand (they never wait);
- after the cycle's VALVE_CMD are sent: one waypoint commit (its workspace check takes a few
  tenths of a ms on the hexapod), when the cycle has room left for it before the next SYNC;
  else it waits for a later cycle (at most COMMIT_MAX_WAIT_CYCLES). What follows it waits
  for the next update.
So a command never overtakes a commit sent before it (a waypoint half reusing a TAG cannot
reach a commit that has not been checked yet), and the cycle's timing never waits for one.
"""

from __future__ import annotations

from collections import deque
from enum import IntEnum

from protocol.enums import AckKind, Command, time_scale_to_wire

IMMEDIATE_COMMANDS = (int(Command.ESTOP), int(Command.DISABLE))
COMMIT_MAX_WAIT_CYCLES = 50      # a commit waits for a cycle with room at most this long, then runs


class Frame(IntEnum):
    COMMAND = 0
    POSITION = 1
    ROTATION = 2
    COMMIT = 3
    TEST = 4


class HostLink:
    def __init__(self):
        self.queue: deque[tuple] = deque()              # (Frame, values)
        # (AckKind, SEQ, result, CTRL_ACK.TIME_SCALE as sent: 0 where it does not apply)
        self.acks: deque[tuple[int, int, int, float]] = deque()
        self.commit_waited = 0                           # cycles the front commit has waited for room

    # -- what the loop decoded ------------------------------------------------------------
    def command(self, command: int, argument: int, seq: int) -> None:
        self.queue.append((Frame.COMMAND, (command, argument, seq)))

    def waypoint_position(self, tag: int, x: float, y: float, z: float) -> None:
        self.queue.append((Frame.POSITION, (tag, x, y, z)))

    def waypoint_rotation(self, tag: int, roll: float, pitch: float, yaw: float) -> None:
        self.queue.append((Frame.ROTATION, (tag, roll, pitch, yaw)))

    def waypoint_commit(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int) -> None:
        self.queue.append((Frame.COMMIT, (tag, seq, segment_time, accel_time, flags)))

    def test(self, mode: int, seq: int, valve_v: float, force_n: float, duration_s: float) -> None:
        self.queue.append((Frame.TEST, (mode, seq, valve_v, force_n, duration_s)))

    # -- carried out by the controller --------------------------------------------------------
    def run_before_update(self, controller) -> None:
        """The frames up to the first commit, in order; ESTOP and DISABLE wherever they are."""
        queue = self.queue
        while queue and queue[0][0] is not Frame.COMMIT:
            self._carry_out(controller, *queue.popleft())
        if queue:
            waiting = [item for item in queue if item[0] is Frame.COMMAND and item[1][0] in IMMEDIATE_COMMANDS]
            for item in waiting:
                queue.remove(item)
                self._carry_out(controller, *item)

    def run_after_write(self, controller, room: bool = True) -> None:
        """The waypoint commit at the front, if there is one and the cycle has `room` for it
        (or it has waited long enough)."""
        if not (self.queue and self.queue[0][0] is Frame.COMMIT):
            return
        if room or self.commit_waited >= COMMIT_MAX_WAIT_CYCLES:
            self.commit_waited = 0
            self._carry_out(controller, *self.queue.popleft())
        else:
            self.commit_waited += 1

    def _carry_out(self, controller, frame: Frame, values: tuple) -> None:
        if frame is Frame.COMMAND:
            command, argument, seq = values
            self.acks.append((AckKind.HOST_CMD, seq, int(controller.host_command(command, argument)), 0.0))
        elif frame is Frame.POSITION:
            controller.stage_position(*values)
        elif frame is Frame.ROTATION:
            controller.stage_rotation(*values)
        elif frame is Frame.COMMIT:
            tag, seq, segment_time, accel_time, flags = values
            result = int(controller.waypoint_commit(tag, seq, segment_time, accel_time, flags))
            scale = time_scale_to_wire(controller.waypoints.time_scale_needed)
            self.acks.append((AckKind.WAYPOINT, seq, result, scale))
        else:
            mode, seq, valve_v, force_n, duration_s = values
            self.acks.append((AckKind.TEST, seq, int(controller.test_command(mode, valve_v, force_n, duration_s)),
                              0.0))
