"""The host on the bus during a HIL run: records every frame, sends HOST_CMD, waypoints and
EMU_CTRL, and waits in bus time (SYNC frames), never in wall time alone.

The recorder is python-can's own writer (`can.Logger`: BLF or ASC by the file's suffix);
frames this host sends are written too (the multicast bus does not echo them back).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

import can

from protocol.codec import CODECS, EncodeStatus, FrameDecoder
from protocol.devices import HEARTBEAT_BASE
from protocol.e2e import RxStatus
from protocol.enums import Ack, AckKind, Command, EmuCommand, NmtState, State, time_scale_from_wire
from protocol.nodes import CONTROLLER_NODE, NODE_IDS
from protocol.outbox import Outbox

# what the host reads: the controller's
CONTROLLER_MESSAGES = ["SYNC", "CTRL_STATUS", "CTRL_ACK", "CTRL_PAYLOAD", "CTRL_CLOCK"]
# ... and leg 1's encoder: the identification tests choose their next input from the last
# one's velocity, as a lab's tool reading the sensor would (scenarios/friction.py)
HOST_MESSAGES = CONTROLLER_MESSAGES + ["LEG_STATE_1"]
ANSWER_WALL_S = 2.0                                             # a named wait's least wall time
TRACK_CYCLES = 2000                                             # leg 1's last positions kept
# the nodes' heartbeats (not the controller's): the emulator is up when they come
NODE_HEARTBEAT_IDS = frozenset(CODECS[f"HEARTBEAT_{node}"].frame_id for node in NODE_IDS.values()
                               if node != CONTROLLER_NODE)


class HostError(RuntimeError):
    """The run cannot go on: no bus traffic, a refused command, a state never reached."""


class PlatformNotHeld(HostError):
    """ENABLE refused BEYOND_CAPACITY: the legs cannot hold the platform where it is; its
    valves stay in HOLD and nothing more can move it."""


class WaypointRefused(HostError):
    """A waypoint the controller refused (`result`; BEYOND_CAPACITY: `time_scale` fits)."""

    def __init__(self, message: str, result: Ack, time_scale: float):
        super().__init__(message)
        self.result, self.time_scale = result, time_scale


class Host:
    def __init__(self, bus: can.BusABC, log_path: str, watch: Callable[[], None] = lambda: None,
                 stall_timeout_s: float = 10.0):
        self.bus = bus
        self.writer = can.Logger(log_path)
        self.watch = watch                      # raises when a child died (called every ~0.2 s)
        self.stall_timeout_s = stall_timeout_s
        self.decoder = FrameDecoder(HOST_MESSAGES)
        self.syncs = 0
        self.leg1_track: deque[tuple[int, float]] = deque(maxlen=TRACK_CYCLES)   # (SYNCs so far, stroke m)
        self.state: State | None = None
        self.fault_code = 0
        self.controller = -1
        self.acks: dict[tuple[int, int], int] = {}
        self.time_scale = math.nan                # the last CTRL_ACK's TIME_SCALE (NaN: not applicable)
        self.payload_kg = math.nan                # the last CTRL_PAYLOAD's MASS (hexapod)
        self.clock = (0, False, 1.0, 0.0)         # the last CTRL_CLOCK: (SYNCs then, MOVING, RATE, MOTION_TIME)
        self.frames_sent = 0
        self.frames_received = 0
        self.node_heartbeats = 0                # CANopen heartbeats of the nodes
        self.heartbeat_at: dict[int, float] = {}  # each node's last heartbeat (host's monotonic clock)
        self.booted_at: dict[int, float] = {}     # node -> its last boot-up (epoch, as the log's)
        self._cmd = Outbox("HOST_CMD")
        self._pos = Outbox("HOST_WAYPOINT_POS")
        self._rot = Outbox("HOST_WAYPOINT_ROT")
        self._time = Outbox("HOST_WAYPOINT_TIME")
        self._emu = Outbox("EMU_CTRL")
        self._kick = Outbox("EMU_KICK")
        self._test = Outbox("HOST_TEST")
        self._cmd_seq = 0
        self._test_seq = 0
        self.waypoint_seq = 0
        self._last_watch = 0.0
        self._sync_id = CODECS["SYNC"].frame_id
        self._status = CODECS["CTRL_STATUS"].index
        self._ack = CODECS["CTRL_ACK"].index
        self._leg1_id, self._leg1_position = CODECS["LEG_STATE_1"].frame_id, CODECS["LEG_STATE_1"].index["POSITION"]

    def new_controller(self) -> None:
        """A new controller process: its E2E counters start afresh, so the checks of the old
        one's must not reject its first frames (its first CTRL_ACK was lost that way)."""
        self.decoder.restart_sender(CODECS["NMT"].schedule.sender)
        self.state = None

    # -- receive ---------------------------------------------------------------------------
    def pump(self, timeout_s: float) -> can.Message | None:
        """Receive and record one frame (None when nothing came within `timeout_s`)."""
        now = time.monotonic()
        if now - self._last_watch > 0.2:
            self._last_watch = now
            self.watch()
        msg = self.bus.recv(timeout_s)
        if msg is None:
            return None
        msg.channel = None                     # BLF/ASC channel numbers, not the bus's name
        self.writer.on_message_received(msg)
        self.frames_received += 1
        if msg.arbitration_id in NODE_HEARTBEAT_IDS:
            self.node_heartbeats += 1
            self.heartbeat_at[msg.arbitration_id] = time.monotonic()
        if HEARTBEAT_BASE < msg.arbitration_id < HEARTBEAT_BASE + 0x80 and msg.dlc and msg.data[0] == NmtState.BOOTUP:
            self.booted_at[msg.arbitration_id - HEARTBEAT_BASE] = msg.timestamp
        status = self.decoder.receive_message(msg)
        if status is RxStatus.OK:
            if msg.arbitration_id == self._sync_id:
                self.syncs += 1
            elif msg.arbitration_id == CODECS["CTRL_STATUS"].frame_id:
                v = self.decoder.values["CTRL_STATUS"]
                self.state = State(int(v[self._status["STATE"]]))
                self.fault_code = int(v[self._status["FAULT_CODE"]])
                self.controller = int(v[self._status["CONTROLLER"]])
            elif msg.arbitration_id == CODECS["CTRL_ACK"].frame_id:
                v = self.decoder.values["CTRL_ACK"]
                key = (int(v[self._ack["KIND"]]), int(v[self._ack["SEQ"]]))
                self.acks[key] = int(v[self._ack["RESULT"]])
                self.time_scale = time_scale_from_wire(float(v[self._ack["TIME_SCALE"]]))
            elif msg.arbitration_id == CODECS["CTRL_PAYLOAD"].frame_id:
                self.payload_kg = float(self.decoder.values["CTRL_PAYLOAD"][CODECS["CTRL_PAYLOAD"].index["MASS"]])
            elif msg.arbitration_id == CODECS["CTRL_CLOCK"].frame_id:
                v, i = self.decoder.values["CTRL_CLOCK"], CODECS["CTRL_CLOCK"].index
                self.clock = (self.syncs, bool(v[i["MOVING"]]), float(v[i["RATE"]]), float(v[i["MOTION_TIME"]]))
            elif msg.arbitration_id == self._leg1_id:
                self.leg1_track.append((self.syncs, float(self.decoder.values["LEG_STATE_1"][self._leg1_position])))
        return msg

    def wait_cycles(self, cycles: int) -> None:
        """Let `cycles` SYNC periods of bus time pass (recording everything)."""
        self.wait_until(lambda: False, cycles, what=None)

    def wait_until(self, condition: Callable[[], bool], max_cycles: int, what: str | None,
                   wall_timeout_s: float | None = None) -> bool:
        """Pump until `condition()` or `max_cycles` SYNCs (or `wall_timeout_s`); HostError if
        `what` is named and the condition was not met, or when the bus goes quiet."""
        end = self.syncs + max_cycles
        last_traffic = time.monotonic()
        give_up = None if wall_timeout_s is None else last_traffic + wall_timeout_s
        # a named wait (an ack, a state) also lasts ANSWER_WALL_S: in lockstep the cycles run as
        # fast as the pair can, and on a loaded machine an ack stamped by the kernel 0.5 ms after
        # its command reached the host's socket after 513 later SYNCs (a campaign of 2 runs)
        floor = last_traffic + (ANSWER_WALL_S if what is not None else 0.0)
        # a start-up wait names its own, longer bound (the processes may still be importing)
        stall_s = max(self.stall_timeout_s, wall_timeout_s or 0.0)
        while ((self.syncs < end or time.monotonic() < floor)
               and (give_up is None or time.monotonic() < give_up)):
            if condition():
                return True
            if self.pump(0.05) is not None:
                last_traffic = time.monotonic()
            elif time.monotonic() - last_traffic > stall_s:
                raise HostError(f"no frame on the bus for {stall_s:g} s "
                                f"(after {self.syncs} SYNCs)")
        if condition():
            return True
        if what is not None:
            raise HostError(f"{what} not reached within {max_cycles} cycles "
                            f"(state {self.state.name if self.state is not None else 'unknown'}, "
                            f"fault code {self.fault_code})")
        return False

    def clock_lag(self, since_syncs: int) -> float:
        """Periods the running trajectory's clock has fallen behind the bus since `since_syncs`
        (the last CTRL_CLOCK: the controller slowed it online); 0 when none is running."""
        syncs, moving, _, motion_time = self.clock
        return max(syncs - since_syncs - motion_time, 0.0) if moving and syncs > since_syncs else 0.0

    def wait_motion_end(self, max_cycles: int) -> None:
        """Until READY after a motion of `max_cycles` periods of its own clock: the periods the
        controller's time scaling took (CTRL_CLOCK) are added as they come, while it runs."""
        start, lag = self.syncs, 0.0
        while True:
            end = start + max_cycles + math.ceil(lag)
            if self.wait_until(lambda: self.state is State.READY, max(end - self.syncs, 1), what=None):
                return
            grown = self.clock_lag(start)
            if grown <= lag or self.state not in (State.RUNNING, State.HOMING):
                raise HostError(f"controller state READY not reached within {self.syncs - start} cycles "
                                f"({max_cycles} on time, {lag:.0f} the controller's time scaling added; "
                                f"state {self.state.name if self.state is not None else 'unknown'}, "
                                f"fault code {self.fault_code})")
            lag = grown

    def wait_heartbeats(self, since: float, ids=NODE_HEARTBEAT_IDS, wall_timeout_s: float = 5.0) -> None:
        """Until every node in `ids` has sent a heartbeat after `since` (time.monotonic()): a node
        that was silent is back before a RESET judges the nodes' heartbeats."""
        self.wait_until(lambda: all(self.heartbeat_at.get(i, -math.inf) > since for i in ids), 10**9,
                        what="a heartbeat from every node", wall_timeout_s=wall_timeout_s)

    def wait_state(self, *states: State, max_cycles: int = 5000, wall_timeout_s: float | None = None) -> None:
        self.wait_until(lambda: self.state in states, max_cycles,
                        what=f"controller state {'/'.join(s.name for s in states)}", wall_timeout_s=wall_timeout_s)

    # -- send ------------------------------------------------------------------------------
    def send(self, box: Outbox) -> None:
        status = box.codec.encode_into(box.values, box.message.data)
        if status is not EncodeStatus.OK:       # never send a saturated waypoint or command
            raise HostError(f"{box.codec.name}: a value is out of the DBC's range or not finite ({status.name})")
        msg = box.message
        msg.timestamp = time.time()
        self.bus.send(msg)
        msg.channel = None
        msg.is_rx = False
        self.writer.on_message_received(msg)
        self.frames_sent += 1

    def _await_ack(self, kind: int, seq: int, what: str, max_cycles: int = 500) -> Ack:
        self.wait_until(lambda: (kind, seq) in self.acks, max_cycles, what=f"CTRL_ACK for {what}")
        return Ack(self.acks.pop((kind, seq)))

    def command(self, command: Command, argument: int = 0, expect_ok: bool = True) -> Ack:
        self._cmd_seq = (self._cmd_seq + 1) % 256
        v, i = self._cmd.values, self._cmd.index
        v[i["COMMAND"]], v[i["ARGUMENT"]], v[i["SEQ"]] = int(command), argument, self._cmd_seq
        self.send(self._cmd)
        result = self._await_ack(AckKind.HOST_CMD, self._cmd_seq, f"HOST_CMD {command.name}")
        if expect_ok and result is not Ack.ACCEPTED:
            raise HostError(f"HOST_CMD {command.name} {argument} refused: {result.name}")
        return result

    def test(self, mode: int, valve_v: float = 0.0, force_n: float = 0.0, duration_s: float = 0.0,
             expect_ok: bool = True) -> Ack:
        """HOST_TEST (test bench identification, chapter 6.4) and its CTRL_ACK."""
        self._test_seq = (self._test_seq + 1) % 256
        v, i = self._test.values, self._test.index
        v[i["MODE"]], v[i["SEQ"]], v[i["VALVE"]] = mode, self._test_seq, valve_v
        v[i["FORCE"]], v[i["DURATION"]] = force_n, duration_s
        self.send(self._test)
        result = self._await_ack(AckKind.TEST, self._test_seq, f"HOST_TEST mode {mode}")
        if expect_ok and result is not Ack.ACCEPTED:
            raise HostError(f"HOST_TEST mode {mode} ({valve_v:g} V, {force_n:g} N, {duration_s:g} s) refused: "
                            f"{result.name}")
        return result

    def waypoint(self, position_m, rpy_rad=(0.0, 0.0, 0.0), segment_time_s: float = 1.0,
                 accel_time_s: float = 0.1, flags: int = 0, expect_ok: bool = True) -> Ack:
        """POS, ROT and TIME frames of one waypoint (TAG = low 4 bits of SEQ); its CTRL_ACK."""
        seq = self.waypoint_seq
        tag = seq & 0x0F
        for box, names, values in ((self._pos, ("X", "Y", "Z"), position_m),
                                   (self._rot, ("ROLL", "PITCH", "YAW"), rpy_rad)):
            box.values[box.index["TAG"]] = tag
            for name, value in zip(names, values):
                box.values[box.index[name]] = value
            self.send(box)
        v, i = self._time.values, self._time.index
        v[i["TAG"]], v[i["SEQ"]], v[i["FLAGS"]] = tag, seq, flags
        v[i["SEGMENT_TIME"]], v[i["ACCEL_TIME"]] = segment_time_s, accel_time_s
        self.send(self._time)
        result = self._await_ack(AckKind.WAYPOINT, seq, f"waypoint {seq}")
        if result is Ack.ACCEPTED:
            self.waypoint_seq = (seq + 1) % 256
        elif expect_ok:
            raise WaypointRefused(f"waypoint {seq} at {[round(float(p) * 1e3, 3) for p in position_m]} mm refused: "
                                  f"{result.name}" + (f" (time scale x{self.time_scale:g} fits)"
                                                       if result is Ack.BEYOND_CAPACITY else ""),
                                  result, self.time_scale)
        return result

    def emulator(self, command: int, target: int = 0, fault: int = 0, load_kg: float = 0.0,
                 param: int = 0) -> None:
        v, i = self._emu.values, self._emu.index
        v[i["COMMAND"]], v[i["TARGET"]], v[i["FAULT"]] = command, target, fault
        v[i["LOAD_MASS"]], v[i["FAULT_PARAM"]] = load_kg, param
        self.send(self._emu)

    def set_load(self, load_kg: float) -> None:
        self.emulator(EmuCommand.SET_LOAD, load_kg=load_kg)

    def kick(self, axis: int, value: float, duration_s: float) -> None:
        """EMU_KICK: push the emulated platform (N along X-Z, N m about ROLL-YAW)."""
        v, i = self._kick.values, self._kick.index
        v[i["AXIS"]], v[i["FORCE"]], v[i["DURATION"]] = axis, value, duration_s
        self.send(self._kick)

    def close(self) -> None:
        self.writer.stop()
