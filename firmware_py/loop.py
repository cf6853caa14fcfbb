"""The controller on the bus: lifecycle (configure -> activate -> run -> shut down) and the
fixed-step cycle SYNC -> collect -> read -> update -> write (DESIGN.md "Timing model").

configure (constructor): codecs compiled at import, every array and CAN message allocated.
activate: NMT start (repeated until every node's heartbeat says OPERATIONAL), then
`hold_cycles` cycles with the valves in HOLD (the first with a Reset pulse, clearing faults
left by an earlier session), then IDLE or READY (auto_enable).
cycle k: send SYNC k; collect cycle k's LEG_STATE frames until all are in or the window
closes (realtime: a fraction of the period; lockstep: a timeout); copy them into the
core; `core.update()`; encode and send VALVE_CMD_* (applied by the valves at SYNC k+1),
CTRL_STATUS when due, CTRL_ACK for host frames, the heartbeat when due.
host work: a waypoint commit is checked against the workspace along its path (0.5-3 ms on
the hexapod), longer than the sensor window. Commits therefore wait in a FIFO and are
checked after the cycle's write, one per cycle; HOST_CMD frames are handled at once
(E-stop and disable take effect in the cycle they arrive in) unless commits are still
waiting, in which case the others keep their place behind them.
pacing: `realtime` - absolute deadlines on the monotonic clock, sleep then spin, late
cycles counted as overruns and skipped (never bursts); a stall (the clock `stall_fault_periods`
past the last SYNC, seen after any wait) faults OVERRUN before anything received late is
acted on: the valves' SYNC watchdog has tripped, and the loop must not carry on as if
nothing happened. `lockstep` - SYNC k+1 as soon as cycle k's exchange is complete.
nodes: a node that boots again (boot-up heartbeat: power cycle, reset) restarts its alive
counters, and the NMT master starts it again on the host's RESET (CiA 302's boot-up of a
slave), so RESET + ENABLE recovers from a plant that was restarted.
shutdown: valves HOLD for `shutdown_hold_cycles`, DISABLED for `shutdown_disable_cycles`.
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from protocol.codec import CODECS, FrameDecoder
from protocol.dbc import sync_counter_overflow
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.outbox import Outbox
from protocol.values import (
    KIND_HOST_CMD,
    KIND_TEST,
    KIND_WAYPOINT,
    NMT_BOOTUP,
    NMT_OPERATIONAL,
    NMT_START,
)

from .core import RESET_GRACE_CYCLES, ControllerCore
from .supervisor import Ack, Command, Fault, State

CONTROLLER_NODE, IMU_NODE = 16, 7
PACINGS = ("realtime", "lockstep")
IMMEDIATE_COMMANDS = (int(Command.ESTOP), int(Command.DISABLE))   # never queued behind host work
HISTORY = 1 << 16                       # cycles kept for the timing percentiles


class ActivationError(RuntimeError):
    """The nodes did not come up (no heartbeat) within the activation timeout."""


@dataclass
class Stats:
    cycles: int = 0
    overruns: int = 0
    e2e_errors: int = 0
    missing_frames: int = 0
    faults: int = 0
    emergencies: int = 0
    host_commands: int = 0
    unknown_frames: int = 0
    frames_sent: int = 0          # every frame the bus accepted (a log must hold as many of ours)


class ControllerLoop:
    def __init__(self, bus, core: ControllerCore, rate_hz: float, pacing: str, clock=time.perf_counter,
                 log=None):
        if pacing not in PACINGS:
            raise ValueError(f"pacing must be one of {PACINGS}, got {pacing!r}")
        self.bus, self.core, self.pacing, self.clock = bus, core, pacing, clock
        self.cfg = core.cfg
        self.period_s = 1.0 / rate_hz
        self.log = log or (lambda text: print(f"controller: {text}", file=sys.stderr, flush=True))
        n = core.n
        self.legs = range(1, n + 1)
        self.nodes = list(self.legs) + ([IMU_NODE] if core.hexapod else [])
        rx = [f"LEG_STATE_{i}" for i in self.legs] + [f"VALVE_STATUS_{i}" for i in self.legs]
        rx += [f"LEG_PRESSURE_{i}" for i in self.legs] + [f"EMCY_{i}" for i in self.nodes]
        rx += [f"HEARTBEAT_{i}" for i in self.nodes] + ["HOST_CMD", "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT",
                                                         "HOST_WAYPOINT_TIME", "HOST_TEST"]
        if core.hexapod:
            rx += ["IMU_ATTITUDE", "IMU_RATE"]
        self.decoder = FrameDecoder(rx)
        self.expected = self.decoder.expected_mask([f"LEG_STATE_{i}" for i in self.legs])
        self._leg_slots = [self.decoder.slot[f"LEG_STATE_{i}"] for i in self.legs]
        self._leg_values = [self.decoder.values[f"LEG_STATE_{i}"] for i in self.legs]
        index = CODECS["LEG_STATE_1"].index
        self._i_pos, self._i_force = index["POSITION"], index["FORCE"]
        self._i_valve, self._i_sensor = index["VALVE_STATE"], index["SENSOR_FAULT"]
        self._leg_of_id = {CODECS[f"LEG_STATE_{i}"].frame_id: i - 1 for i in self.legs}
        self._heartbeat_of_id = {CODECS[f"HEARTBEAT_{i}"].frame_id: i for i in self.nodes}
        self._sender_of_node = {i: CODECS[f"HEARTBEAT_{i}"].schedule.sender for i in self.nodes}
        self._emcy_of_id = {CODECS[f"EMCY_{i}"].frame_id: i for i in self.nodes}
        self._ids = {name: CODECS[name].frame_id for name in ("HOST_CMD", "HOST_WAYPOINT_POS",
                                                                "HOST_WAYPOINT_ROT", "HOST_WAYPOINT_TIME", "HOST_TEST")}
        index = CODECS["LEG_PRESSURE_1"].index
        self._i_pa, self._i_pb = index["PA"], index["PB"]
        self._i_pfault = (index["SENSOR_FAULT_A"], index["SENSOR_FAULT_B"])
        self._pressure_of_id = {CODECS[f"LEG_PRESSURE_{i}"].frame_id: i - 1 for i in self.legs}
        self._pressure_values = [self.decoder.values[f"LEG_PRESSURE_{i}"] for i in self.legs]
        self._imu_attitude_id = CODECS["IMU_ATTITUDE"].frame_id if core.hexapod else -1
        if core.hexapod:                             # views made once: the cycle copies through them
            attitude, index = self.decoder.values["IMU_ATTITUDE"], CODECS["IMU_ATTITUDE"].index
            self._imu_status = attitude[index["STATUS"]:index["STATUS"] + 1]
            self._imu_rpy = attitude[index["ROLL"]:index["YAW"] + 1]
        self.out_sync = Outbox("SYNC")
        self.out_nmt = Outbox("NMT")
        self.out_cmd = [Outbox(f"VALVE_CMD_{i}") for i in self.legs]
        self.out_status = Outbox("CTRL_STATUS")
        self.out_ack = Outbox("CTRL_ACK")
        self.out_heartbeat = Outbox(f"HEARTBEAT_{CONTROLLER_NODE}")
        self._status_schedule = CODECS["CTRL_STATUS"].schedule
        c = CODECS["VALVE_CMD_1"].index
        self._i_d, self._i_h, self._i_m, self._i_r, self._i_sp = (c[k] for k in ("CW_D", "CW_H", "CW_M", "CW_R",
                                                                                   "SPOOL_SETPOINT"))
        self._overflow = sync_counter_overflow()
        self.sync_counter = 0
        self.heartbeat_seen = {node: -math.inf for node in self.nodes}
        self.nmt_state = {node: -1 for node in self.nodes}
        self.acks: list[tuple[int, int, int]] = []
        self.host_work: deque[tuple] = deque()      # (handler, values) in arrival order
        self.stats = Stats()
        self.compute_s = np.zeros(HISTORY)
        self.period_error_s = np.zeros(HISTORY)
        self._compute_max = 0.0
        self._period_error_max = 0.0
        self._last_sync = math.nan
        self._next_heartbeat = 0.0
        self._overrun = False
        self._stall_s = self.cfg.stall_fault_periods * self.period_s if pacing == "realtime" else math.inf
        self._forced: bool | None = None            # shutdown: True HOLD, False DISABLED

    # -- receive --------------------------------------------------------------------------
    def dispatch(self, msg) -> None:
        status = self.decoder.receive_message(msg)
        frame_id = msg.arbitration_id
        if status is RxStatus.UNKNOWN_ID:
            self.stats.unknown_frames += 1
            return
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                self.stats.e2e_errors += 1
                leg = self._leg_of_id.get(frame_id)
                if leg is not None:
                    self.core.meas_bad[leg] = True
            return
        if frame_id in self._leg_of_id:
            return                                   # read() copies it after the window
        leg = self._pressure_of_id.get(frame_id)
        if leg is not None:                          # SI (Pa) from the codec
            values = self._pressure_values[leg]
            if values[self._i_pfault[0]] or values[self._i_pfault[1]]:
                self.core.pressure_seen[leg] = False         # a transducer fault: no piston force
                return
            self.core.meas_pa[leg] = values[self._i_pa]
            self.core.meas_pb[leg] = values[self._i_pb]
            self.core.pressure_seen[leg] = True
            return
        if frame_id == self._imu_attitude_id:
            if self._imu_status[0] == 0:             # 0 = valid
                self.core.meas_attitude[:] = self._imu_rpy
                self.core.attitude_fresh = True
            return
        node = self._heartbeat_of_id.get(frame_id)
        if node is not None:
            self.heartbeat_seen[node] = self.clock()
            state = int(self.decoder.values[f"HEARTBEAT_{node}"][0])
            if state == NMT_BOOTUP:                  # the node restarted: so did its alive counters
                self.decoder.restart_sender(self._sender_of_node[node])
            self.nmt_state[node] = state
            return
        node = self._emcy_of_id.get(frame_id)
        if node is not None:
            self.stats.emergencies += 1
            if self.decoder.values[f"EMCY_{node}"][0] != 0 and self.core.reset_cycles == 0:
                self.core.fault(Fault.VALVE_FAULT)
            return
        if frame_id == self._ids["HOST_CMD"]:
            _, _, command, argument, seq = self.decoder.values["HOST_CMD"]
            self.stats.host_commands += 1
            values = (int(command), int(argument), int(seq))
            if self.host_work and values[0] not in IMMEDIATE_COMMANDS:
                self.host_work.append((self._host_command, values))
            else:
                self._host_command(*values)
        elif frame_id == self._ids["HOST_WAYPOINT_POS"]:
            _, _, tag, x, y, z = self.decoder.values["HOST_WAYPOINT_POS"]
            self._stage(self.core.waypoint_position, (int(tag), float(x), float(y), float(z)))
        elif frame_id == self._ids["HOST_WAYPOINT_ROT"]:
            _, _, tag, roll, pitch, yaw = self.decoder.values["HOST_WAYPOINT_ROT"]
            self._stage(self.core.waypoint_rotation, (int(tag), float(roll), float(pitch), float(yaw)))
        elif frame_id == self._ids["HOST_WAYPOINT_TIME"]:
            _, _, tag, seq, segment, accel, flags = self.decoder.values["HOST_WAYPOINT_TIME"]
            self.host_work.append((self._commit, (int(tag), int(seq), float(segment), float(accel), int(flags))))
        elif frame_id == self._ids["HOST_TEST"]:
            _, _, mode, seq, valve, force, duration = self.decoder.values["HOST_TEST"]
            self._stage(self._test, (int(mode), int(seq), float(valve), float(force), float(duration)))

    # -- host work (outside the sensor window) ----------------------------------------------
    def _host_command(self, command: int, argument: int, seq: int) -> None:
        result = self.core.host_command(command, argument)
        self.acks.append((KIND_HOST_CMD, seq, int(result)))
        if command == Command.RESET and result is Ack.ACCEPTED and any(
                self.nmt_state[n] != NMT_OPERATIONAL for n in self.nodes):
            self._nmt_start()                        # nodes that rebooted since activation

    def _nmt_start(self) -> None:
        self.out_nmt.values[:] = (NMT_START, 0)
        self._send(self.out_nmt)

    def _stage(self, handler, values: tuple) -> None:
        """Waypoint halves: at once, unless commits wait (a reused TAG must not overtake them)."""
        if self.host_work:
            self.host_work.append((handler, values))
        else:
            handler(*values)

    def _test(self, mode: int, seq: int, valve: float, force: float, duration: float) -> None:
        self.acks.append((KIND_TEST, seq, int(self.core.test_command(mode, valve, force, duration))))

    def _commit(self, tag: int, seq: int, segment: float, accel: float, flags: int) -> None:
        self.acks.append((KIND_WAYPOINT, seq, int(self.core.waypoint_time(tag, seq, segment, accel, flags))))

    def do_host_work(self) -> None:
        """After the cycle's write: queued host frames in order, up to and including one commit."""
        while self.host_work:
            handler, values = self.host_work.popleft()
            handler(*values)
            if handler == self._commit:
                return

    def _collect(self, deadline: float) -> None:
        """Receive until every LEG_STATE of the cycle is in or the window closes; frames
        already waiting in the receive queue when it closes arrived in time and are taken."""
        while not self._all_fresh():
            remaining = deadline - self.clock()
            msg = self.bus.recv(timeout=max(remaining, 0.0))
            self._check_stall()
            if msg is None:
                if remaining <= 0.0:
                    return
                continue
            self.dispatch(msg)

    def _all_fresh(self) -> bool:
        fresh = self.decoder.fresh
        for slot in self._leg_slots:
            if not fresh[slot]:
                return False
        return True

    def _drain_until(self, deadline: float) -> None:
        """Between cycles: handle host and node frames until `deadline - spin`, then spin."""
        spin = self.cfg.spin_s
        while True:
            remaining = deadline - spin - self.clock()
            if remaining <= 0.0:
                break
            msg = self.bus.recv(timeout=remaining)
            self._check_stall()
            if msg is not None:
                self.dispatch(msg)
        while self.clock() < deadline:
            pass

    def _check_stall(self) -> None:
        """Realtime: the process was not running for longer than the valves' watchdog."""
        if self.clock() - self._last_sync > self._stall_s and self.core.state is not State.BOOT:
            self.core.fault(Fault.OVERRUN)

    # -- read / write ---------------------------------------------------------------------
    def _read(self) -> None:
        core, fresh = self.core, self.decoder.fresh
        for leg, slot in enumerate(self._leg_slots):
            values = self._leg_values[leg]
            ok = bool(fresh[slot])
            core.meas_fresh[leg] = ok
            if ok:
                core.meas_y[leg] = values[self._i_pos]
                core.meas_force[leg] = values[self._i_force]
                core.valve_state[leg] = int(values[self._i_valve])
                core.meas_sensor_fault[leg] = values[self._i_sensor] != 0.0

    def _send(self, outbox: Outbox) -> None:
        if outbox.encode():
            try:
                self.bus.send(outbox.message)
            except Exception as exc:               # a full queue or a bus error drops the frame
                self.log(f"send {outbox.codec.name} failed: {exc}")
                return
            self.stats.frames_sent += 1

    def _write(self) -> None:
        core = self.core
        if self._forced is not None:
            core.force_outputs(self._forced)
        for leg, box in enumerate(self.out_cmd):
            v = box.values
            v[self._i_d] = core.cw_d[leg]
            v[self._i_h] = core.cw_h[leg]
            v[self._i_m] = core.cw_m[leg]
            v[self._i_r] = core.cw_r[leg]
            v[self._i_sp] = core.spool[leg]
            self._send(box)
        if self._status_schedule.due(self.sync_counter):
            v = self.out_status.values
            i = self.out_status.index
            v[i["STATE"]] = int(core.state)
            v[i["FAULT_CODE"]] = int(core.sup.fault_code)
            v[i["CONTROLLER"]] = core.sup.controller
            v[i["COMPUTE_TIME_MAX"]] = self._compute_max
            v[i["PERIOD_ERROR_MAX"]] = self._period_error_max
            v[i["OVERRUNS"]] = self.stats.overruns % 256
            v[i["ACTIVE_WAYPOINT"]] = core.active_waypoint % 256
            self._send(self.out_status)
            self._compute_max = 0.0
            self._period_error_max = 0.0
        while self.acks:
            kind, seq, result = self.acks.pop(0)
            v = self.out_ack.values
            i = self.out_ack.index
            v[i["KIND"]], v[i["SEQ"]], v[i["RESULT"]], v[i["QUEUE_FREE"]] = kind, seq % 256, result, core.queue_free()
            self._send(self.out_ack)

    def _heartbeats(self, now: float) -> None:
        if now >= self._next_heartbeat:
            self.out_heartbeat.values[0] = NMT_OPERATIONAL
            self._send(self.out_heartbeat)
            self._next_heartbeat = now + self.cfg.heartbeat_s
        if self.core.state is State.BOOT:
            return
        limit = self.cfg.heartbeat_timeout_s
        for node in self.nodes:
            if now - self.heartbeat_seen[node] > limit:
                self.core.fault(Fault.HEARTBEAT_LOST)

    # -- one cycle ------------------------------------------------------------------------
    def cycle(self) -> None:
        """SYNC, collect, read, update, write, then host work (pacing is `_run_cycles`'s)."""
        now = self.clock()
        self._check_stall()
        k = self.stats.cycles % HISTORY
        if not math.isnan(self._last_sync):
            error = abs(now - self._last_sync - self.period_s)
            self.period_error_s[k] = error
            self._period_error_max = max(self._period_error_max, error)
        self._last_sync = now
        self.sync_counter = self.sync_counter % self._overflow + 1
        self.out_sync.values[0] = self.sync_counter
        self._send(self.out_sync)
        self.decoder.begin_cycle()
        self.core.meas_bad[:] = False
        window = self.cfg.sync_window_fraction * self.period_s if self.pacing == "realtime" \
            else self.cfg.lockstep_timeout_s
        self._collect(now + window)
        self.stats.missing_frames += self.decoder.end_cycle(self.expected)
        start = self.clock()
        self._read()
        faults_before = self.core.sup.faults
        self.core.update(self._overrun)
        self._write()
        self._heartbeats(start)
        self.stats.faults += self.core.sup.faults - faults_before
        compute = self.clock() - start
        self.compute_s[k] = compute
        self._compute_max = max(self._compute_max, compute)
        self.stats.cycles += 1
        if self.core.sup.faults != faults_before:
            self._log_fault(now)
        self.do_host_work()                     # after the write: its cost never delays VALVE_CMD

    def _log_fault(self, sync_time: float) -> None:
        """One stderr line when the controller faults (an event, not the steady cycle): which
        legs' frames were missing or rejected how many cycles in a row, and what the receiver
        last made of each; the leg a SENSOR_TIMEOUT or E2E_ERROR came from is named here."""
        core = self.core
        last = [RxStatus(int(self.decoder.last_status[slot])).name for slot in self._leg_slots]
        self.log(f"fault {core.sup.fault_code.name} at cycle {self.stats.cycles}: missing in a row "
                 f"{core.missing.tolist()}, rejected in a row {core.bad.tolist()}, last LEG_STATE status {last}, "
                 f"overruns in a row {core.overruns_in_row}, this cycle {1e6 * (self.clock() - sync_time):.0f} us "
                 f"after its SYNC")

    # -- lifecycle ------------------------------------------------------------------------
    def activate(self, should_stop=lambda: False) -> None:
        """NMT start until every node reports OPERATIONAL, then HOLD cycles, then IDLE/READY."""
        cfg = self.cfg
        give_up = self.clock() + cfg.activation_timeout_s
        next_start = 0.0
        while not all(self.nmt_state[n] == NMT_OPERATIONAL for n in self.nodes):
            now = self.clock()
            if now > give_up or should_stop():
                missing = [n for n in self.nodes if self.nmt_state[n] != NMT_OPERATIONAL]
                raise ActivationError(f"no OPERATIONAL heartbeat from node(s) {missing} within "
                                      f"{cfg.activation_timeout_s:g} s")
            if now >= next_start:
                self._nmt_start()
                next_start = now + 0.2
            msg = self.bus.recv(timeout=0.02)
            if msg is not None:
                self.dispatch(msg)
        self.core.reset_cycles = RESET_GRACE_CYCLES  # one Reset pulse: clears faults left from before
        self._run_cycles(cfg.hold_cycles, should_stop)
        self.core.activated(cfg.auto_enable)
        self.log(f"active: rig={self.core.rig} state={self.core.state.name} pacing={self.pacing} "
                 f"rate={1.0 / self.period_s:g} Hz")

    def _run_cycles(self, count: int | None, should_stop) -> None:
        deadline = self.clock()
        done = 0
        while (count is None or done < count) and not should_stop():
            if self.pacing == "realtime":
                self.cycle()
                deadline += self.period_s
                now = self.clock()
                self._overrun = now > deadline
                if self._overrun:
                    self.stats.overruns += 1
                    deadline += math.ceil((now - deadline) / self.period_s) * self.period_s
                self._drain_until(deadline)
            else:
                self.cycle()
            done += 1

    def run(self, should_stop) -> None:
        self._run_cycles(None, should_stop)

    def shutdown(self) -> None:
        """Valves to HOLD, then DISABLED, over a few cycles; SYNC keeps running meanwhile."""
        never = lambda: False  # noqa: E731
        self._forced = True
        self._run_cycles(self.cfg.shutdown_hold_cycles, never)
        self._forced = False
        self._run_cycles(self.cfg.shutdown_disable_cycles, never)

    def timing(self) -> dict:
        n = min(self.stats.cycles, HISTORY)
        out = {}
        for name, data in (("compute_us", self.compute_s[:n]), ("period_error_us", self.period_error_s[:n])):
            if n:
                p50, p99 = np.percentile(data, [50, 99]) * 1e6
                out[name] = {"p50": round(float(p50), 1), "p99": round(float(p99), 1),
                             "max": round(float(data.max()) * 1e6, 1)}
        return out

    def summary(self) -> dict:
        s = self.stats
        return {"rig": self.core.rig, "controller": self.core.sup.controller, "pacing": self.pacing,
                "cycles": s.cycles, "overruns": s.overruns, "e2e_errors": s.e2e_errors,
                "missing_frames": s.missing_frames, "faults": s.faults, "fault_code": self.core.sup.fault_code.name,
                "state": self.core.state.name, "emergencies": s.emergencies, "host_commands": s.host_commands,
                "frames_sent": s.frames_sent, "timing": self.timing()}
