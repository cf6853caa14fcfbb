"""The host's frames on their way into the controller, in arrival order, each carried out at
its place in the cycle, and the acknowledgements going back.

The loop only queues what it decoded. The controller carries the queue out:
- in its update, before the reference is computed: the frames at the front up to the first
  waypoint commit (commands, waypoint halves, tests), and ESTOP and DISABLE wherever they
  stand (they never wait);
- after the cycle's VALVE_CMD are sent: the front waypoint commit, stage by stage (its check
  takes ~2.5 ms on the hexapod here, in stages of at most ~0.35 ms), each stage only while
  the cycle has `commit_room_us` left before the next SYNC; the rest in later cycles. A
  commit that found no room for COMMIT_MAX_WAIT_CYCLES then runs a stage a cycle regardless,
  but not right after an overrun (so a commit never makes overruns in a row).
  Its CTRL_ACK goes out when its last stage is done; what follows it waits until then.
So a command never overtakes a commit sent before it (a waypoint half reusing a TAG cannot
reach a commit that has not been checked yet), and the cycle's timing never waits for one.
"""

from __future__ import annotations

import math
from collections import deque
from enum import IntEnum

from protocol.enums import AckKind, Command, time_scale_to_wire

IMMEDIATE_COMMANDS = (int(Command.ESTOP), int(Command.DISABLE))
COMMIT_MAX_WAIT_CYCLES = 50      # a commit waits for room at most this long, then runs a stage a cycle


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
        self._commit = None                              # the front commit's stages, once begun

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

    def run_after_write(self, controller, time_left_s: float = math.inf, room_s: float = 0.0, clock=None,
                        may_force: bool = True) -> None:
        """The front waypoint commit's stages while the cycle has `room_s` left before the next
        SYNC (`time_left_s` at the call, less what the stages took by `clock`; without a clock,
        all of them when there is room). Without room, after COMMIT_MAX_WAIT_CYCLES, one stage
        where `may_force` (the loop's previous cycle kept its deadline)."""
        if not (self.queue and self.queue[0][0] is Frame.COMMIT):
            return
        if time_left_s < room_s and (self.commit_waited < COMMIT_MAX_WAIT_CYCLES or not may_force):
            self.commit_waited += 1
            return
        if self._commit is None:
            tag, seq, segment_time, accel_time, flags = self.queue[0][1]
            self._commit = controller.waypoint_commit_stages(tag, seq, segment_time, accel_time, flags)
        start = clock() if clock is not None else 0.0
        while True:
            try:
                next(self._commit)
            except StopIteration as done:
                self._commit_done(controller, done.value)
                return
            left = time_left_s - (clock() - start) if clock is not None else time_left_s
            if left < room_s:
                return

    def _commit_done(self, controller, result) -> None:
        _, (_, seq, *_) = self.queue.popleft()
        self._commit, self.commit_waited = None, 0
        scale = time_scale_to_wire(controller.waypoints.time_scale_needed)
        self.acks.append((AckKind.WAYPOINT, seq, int(result), scale))

    def _carry_out(self, controller, frame: Frame, values: tuple) -> None:
        if frame is Frame.COMMAND:
            command, argument, seq = values
            self.acks.append((AckKind.HOST_CMD, seq, int(controller.host_command(command, argument)), 0.0))
        elif frame is Frame.POSITION:
            controller.stage_position(*values)
        elif frame is Frame.ROTATION:
            controller.stage_rotation(*values)
        else:
            mode, seq, valve_v, force_n, duration_s = values
            self.acks.append((AckKind.TEST, seq, int(controller.test_command(mode, valve_v, force_n, duration_s)),
                              0.0))
