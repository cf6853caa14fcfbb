"""The emulator on the bus: leg nodes (CiA 408 valve driver + encoder, load cell, pressure
sensors), the IMU node (hexapod), fault injection, and the process loop.

Per SYNC k (docs/ARCHITECTURE.md "The emulator's cycle"):
1. every valve applies the command latched during cycle k-1 (state machine, setpoint) and
   checks its command timeout and spool deviation; EMCY on a fault;
2. every OPERATIONAL sensor node samples the rig as it is at t_k and sends its frames due on
   this SYNC (LEG_STATE every SYNC, with the valve state just applied; LEG_PRESSURE,
   VALVE_STATUS, IMU at their divisors), the IMU's first and each leg's LEG_STATE last: the
   controller closes its window on the LEG_STATEs, and one socket keeps this order, so the
   samples of SYNC k it uses are those of cycle k, never by chance the next cycle's;
3. the rig integrates exactly one SYNC period with the applied spool setpoints.
So the emulator follows whoever produces SYNC, in realtime and lockstep pacing alike.
Heartbeats and the SYNC-loss watchdog run on the wall clock, like a real node's timers.
When the watchdog trips (the controller died or stalled), the plant does not stop with the
bus: the physics catches up to the trip with the valves as they were, then runs on the
wall clock with the valves in FAULT_HOLD, and EMU_TRUTH reports where the mechanism went
(what a fault test measures), until SYNC returns.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field

import can
import mujoco
import numpy as np

from physics import hydraulics as hy
from plant_emulator.params import EmulatorConfig
from plant_emulator.valve_node import Emergency, ValveDriver, ValveState
from program.realtime import percentiles_us
from protocol.codec import CODECS, FrameDecoder
from protocol.dbc import sync_counter_overflow
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.enums import EmuCommand, EmuFault, NmtCommand, NmtState
from protocol.nodes import CONTROLLER_NODE, IMU_NODE, rig_nodes
from protocol.outbox import Outbox

# per SYNC (seconds each, `phase_s`): from the SYNC's handling to the last sampled frame sent;
# the valve nodes' SYNC handling; sampling, encoding and sending; the physics step; the whole
SYNC_PHASES = ("response", "nodes", "send", "physics", "total")
SP_RESPONSE, SP_NODES, SP_SEND, SP_PHYSICS, SP_TOTAL = range(len(SYNC_PHASES))
SYNC_HISTORY = 1 << 16
BABBLE_ID = 0x601                    # not in the DBC (an SDO request id of node 1)
FREE_RUN_CATCH_UP_STEPS = 25         # free run: periods of physics per poll at most (a late wake-up)
# EMU_CTRL.FAULT (the DBC's value table). REPEAT: the node re-sends its previous frame (a
# frozen alive counter); LEG_JAM: the cylinder's rod seized (mechanical; the valve still works).
# ENCODER_DRIFT, FORCE_STUCK, FORCE_ZERO: the leg's sensors; SPOOL_STUCK: the spool held open
# whatever the valve does (mechanical); SUPPLY_DROP: the power unit delivers part of its pressure;
# FRAME_LOSS: each frame of the node lost at random; SEAL_LEAK: a worn piston seal (mechanical).
# FAULT_PARAM is the fault's value for these (until cleared), its duration in SYNCs for the others
VALUE_PARAM_FAULTS = (EmuFault.BABBLE, EmuFault.OUT_OF_RANGE, EmuFault.ENCODER_DRIFT, EmuFault.SPOOL_STUCK,
                      EmuFault.SUPPLY_DROP, EmuFault.FRAME_LOSS, EmuFault.SEAL_LEAK)
KNOWN_FAULTS = frozenset(int(kind) for kind in EmuFault if kind is not EmuFault.NONE)
SYNC_TIMEOUT_EVENT = "emulator: event sync_timeout"   # a stderr line per SYNC-watchdog trip (JSON after it)
# a stderr line per injected fault, at the first SYNC that sees it: the fault's onset cycle
# (the host's EMU_CTRL and the controller's SYNC race to this process: only it knows the order)
FAULT_ONSET_EVENT = "emulator: event fault_onset"


def attitude_rpy(quat_wxyz) -> np.ndarray:
    """(roll, pitch, yaw) of the bus's convention R = Rz(yaw) Ry(pitch) Rx(roll), from
    MuJoCo's rotation matrix of the body's quaternion (SciPy's Rotation is the tests' oracle)."""
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(quat_wxyz, dtype=float))
    pitch = math.asin(max(-1.0, min(1.0, -rot[6])))
    return np.array([math.atan2(rot[7], rot[8]), pitch, math.atan2(rot[3], rot[0])])


@dataclass
class Counters:
    syncs: int = 0
    frames_in: int = 0
    frames_out: int = 0
    e2e_errors: int = 0
    sync_sequence_errors: int = 0
    valve_faults: int = 0
    emergencies: int = 0
    unknown_frames: int = 0
    host_stalls: int = 0              # this process not scheduled for > 1 SYNC period (node clocks paused)
    host_stall_max_s: float = 0.0
    free_run_steps: int = 0           # periods of physics run on the wall clock after a lost SYNC
    kicks: int = 0                    # EMU_KICK pushes applied to the platform
    plant_unstable: int = 0           # periods whose physics had diverged (MuJoCo reset, or not finite)
    plant_unstable_first_s: float | None = None     # the simulated time of the first of them
    injected: dict = field(default_factory=dict)
    # every SYNC-watchdog trip: when (epoch s), and how late this process woke for it (ms): a
    # real node's hardware timer fires on time; ours is this process's wake-up (hil faults, case 1)
    sync_timeouts: list = field(default_factory=list)
    fault_onsets: list = field(default_factory=list)    # every injection: its SYNC counter and epoch time

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("syncs", "frames_in", "frames_out", "e2e_errors",
                                              "sync_sequence_errors", "valve_faults", "emergencies",
                                              "unknown_frames", "host_stalls", "free_run_steps",
                                              "kicks", "plant_unstable", "plant_unstable_first_s")} | {
            "host_stall_max_ms": round(self.host_stall_max_s * 1e3, 3), "injected": dict(self.injected),
            "sync_timeouts": list(self.sync_timeouts), "fault_onsets": list(self.fault_onsets)}


class Emulator:
    """Nodes of one rig on one bus. `handle(msg)` for every received frame, `poll(now)` often."""

    def __init__(self, bus: can.BusABC | None, rig, cfg: EmulatorConfig, clock=time.monotonic):
        self.bus, self.rig, self.cfg, self.clock = bus, rig, cfg, clock
        rig.warm_up()                     # kernels loaded before the first SYNC, not in it
        self.legs = range(1, rig.n_legs + 1)
        self.has_imu = rig.n_legs == 6
        self.nodes = rig_nodes(rig.n_legs)
        self.valves = {n: self._new_valve() for n in self.legs}
        self.spool_demand = np.zeros(rig.n_legs)    # each valve's own demand over the last period
        self.nmt = {n: NmtState.BOOTUP for n in self.nodes}
        names = ["NMT", "SYNC", "EMU_CTRL", "EMU_KICK"] + [f"VALVE_CMD_{n}" for n in self.legs]
        self.decoder = FrameDecoder(names)
        self._cmd_slot = {CODECS[f"VALVE_CMD_{n}"].frame_id: n for n in self.legs}
        self._ids = {name: CODECS[name].frame_id for name in names}
        self.out = {name: Outbox(name) for name in self._tx_names()}
        self.counters = Counters()
        self.rng = np.random.default_rng(cfg.sensors.seed)
        self.sync_counter = 0
        self.last_sync_time: float | None = None
        self.last_sync_waited_s = 0.0          # how long that SYNC sat in the socket first
        self.sync_lost_reported = False
        self.next_heartbeat = 0.0
        self.faults: dict[tuple[int, int], list] = {}     # (target, kind) -> [remaining cycles or -1, param]
        self._held: dict[str, bytes] = {}                  # REORDER: frame held back per message
        self._last_sent: dict[str, bytes] = {}             # REPEAT: the frame sent before the fault
        self._free_run_next: float | None = None           # wall time of the next free-run step
        self._delayed: list[can.Message] = []              # DELAY: frames sent at the next SYNC
        # what a sensor fault took at its onset, per (node, fault): STUCK the readings it froze,
        # FORCE_STUCK the force, ENCODER_DRIFT the rig time; dropped when the fault clears
        self._onset_values: dict[tuple[int, int], object] = {}
        self._onsets: list[dict] = []                      # injected since the last SYNC
        self._ignore_commands = 0
        divisors = {"LEG_PRESSURE": cfg.nodes.leg_pressure_divisor, "VALVE_STATUS": cfg.nodes.valve_status_divisor,
                    "IMU": cfg.nodes.imu_divisor}
        self._period = {}                                   # SYNC-driven frames: send every n-th SYNC
        for name in self.out:
            dbc_period = CODECS[name].schedule.sync_period
            if dbc_period > 0:
                override = next((d for prefix, d in divisors.items() if name.startswith(prefix)), 0)
                self._period[name] = override or dbc_period
        self._overflow = sync_counter_overflow()
        self.phase_s = np.zeros((SYNC_HISTORY, len(SYNC_PHASES)))     # per SYNC, seconds

    def _new_valve(self) -> ValveDriver:
        nodes = self.cfg.nodes
        return ValveDriver(nodes.command_timeout_syncs, nodes.spool_jam_threshold, nodes.spool_jam_syncs)

    def _tx_names(self) -> list[str]:
        names = []
        for n in self.legs:
            names += [f"LEG_STATE_{n}", f"LEG_PRESSURE_{n}", f"VALVE_STATUS_{n}", f"EMCY_{n}", f"HEARTBEAT_{n}"]
        if self.has_imu:
            names += ["IMU_ATTITUDE", "IMU_RATE", f"EMCY_{IMU_NODE}", f"HEARTBEAT_{IMU_NODE}"]
        return names + ["EMU_TRUTH"]

    # -- transmit -----------------------------------------------------------------------------
    def _send(self, message: can.Message) -> None:
        if self.bus is not None:
            try:
                self.bus.send(message)
            except can.CanError:
                return                      # a full queue drops the frame, as a controller would
        self.counters.frames_out += 1

    def _fault(self, target: int, kind: EmuFault):
        """The active injected fault `kind` on `target` ([remaining, param]) or None."""
        return self.faults.get((target, kind))

    def _emit(self, node: int, name: str) -> None:
        """Encode and send a node's frame through the injected frame faults."""
        box = self.out[name]
        if not box.encode():
            return
        if not self.faults:                    # the common case: nothing injected
            self._last_sent[name] = bytes(box.message.data)
            self._send(box.message)
            return
        if self._fault(node, EmuFault.SILENT) or self._fault(node, EmuFault.DROP):
            return
        loss = self._fault(node, EmuFault.FRAME_LOSS)
        if loss is not None and self.rng.random() * 100.0 < loss[1]:
            return
        message = box.message
        if self._fault(node, EmuFault.REPEAT):
            last = self._last_sent.get(name)
            if last is not None:               # the frame before the fault again, counter and all
                message = can.Message(arbitration_id=message.arbitration_id, data=last, is_extended_id=False)
        else:
            self._last_sent[name] = bytes(message.data)
        if self._fault(node, EmuFault.CORRUPT):
            message = can.Message(arbitration_id=message.arbitration_id, data=bytearray(message.data),
                                  is_extended_id=False)
            message.data[-1] ^= 0x01          # after the CRC: the receiver sees a CRC error
        if self._fault(node, EmuFault.DELAY):
            self._delayed.append(can.Message(arbitration_id=message.arbitration_id, data=bytes(message.data),
                                             is_extended_id=False))
            return
        if self._fault(node, EmuFault.REORDER):
            held = self._held.pop(name, None)
            if held is None:                   # hold this one; the next goes out before it
                self._held[name] = bytes(message.data)
                return
            self._send(message)
            self._send(can.Message(arbitration_id=message.arbitration_id, data=held, is_extended_id=False))
            return
        self._send(message)
        if self._fault(node, EmuFault.DUPLICATE):
            self._send(message)

    def _emergency(self, node: int, emergency: Emergency) -> None:
        box = self.out[f"EMCY_{node}"]
        box.values[:] = (emergency.error_code, emergency.error_register, int(emergency.state),
                         int(emergency.reason), self.sync_counter % 256, emergency.info)
        self.counters.emergencies += 1
        if emergency.error_code:
            self.counters.valve_faults += 1
        if not self._fault(node, EmuFault.SILENT) and box.encode():
            self._send(box.message)

    def _heartbeat(self, node: int) -> None:
        box = self.out[f"HEARTBEAT_{node}"]
        box.values[0] = self.nmt[node]
        if not self._fault(node, EmuFault.SILENT) and box.encode():
            self._send(box.message)

    def _heartbeats(self) -> None:
        for n in self.nodes:
            self._heartbeat(n)

    # -- lifecycle ----------------------------------------------------------------------------
    def boot(self) -> None:
        """Power-on: valves INIT -> DISABLED, boot-up heartbeats, then PRE-OPERATIONAL."""
        for valve in self.valves.values():
            valve.boot()
        for n in self.nodes:
            self.nmt[n] = NmtState.BOOTUP
        self._heartbeats()
        for n in self.nodes:
            self.nmt[n] = NmtState.OPERATIONAL if self.cfg.nodes.nmt_autostart else NmtState.PRE_OPERATIONAL
        self.next_heartbeat = self.clock() + self.cfg.nodes.heartbeat_s

    def poll(self, now: float | None = None) -> float:
        """Timers: heartbeats and the SYNC watchdog. Returns seconds until the next timer."""
        now = self.clock() if now is None else now
        if now >= self.next_heartbeat:
            self._heartbeats()
            self.next_heartbeat = now + self.cfg.nodes.heartbeat_s
        period = self.cfg.nodes.sync_period_s
        limit = self.cfg.nodes.sync_timeout_periods * period
        if self.last_sync_time is not None and not self.sync_lost_reported and now - self.last_sync_time > limit:
            self.sync_lost_reported = True
            woke_late = now - self.last_sync_time - limit
            trip = {"t_epoch_s": time.time(), "woke_late_ms": round(woke_late * 1e3, 3),
                    "sync_waited_ms": round(self.last_sync_waited_s * 1e3, 3),
                    "late_ms": round((woke_late + self.last_sync_waited_s) * 1e3, 3)}
            self.counters.sync_timeouts.append(trip)
            # the valves go to FAULT_HOLD now, and say so at once (EMCY); the physics then
            # catches up to now with the setpoints the rig still has (the last SYNC
            # integrated one period, the valves kept their setpoints until the trip)
            for n, valve in self.valves.items():
                emergency = valve.sync_lost((now - self.last_sync_time) / period)
                if emergency is not None:
                    self._emergency(n, emergency)
            # then on stderr (a process killed later never writes its summary): after the
            # EMCYs, which a write to a busy disk must not delay
            print(f"{SYNC_TIMEOUT_EVENT} {json.dumps(trip)}", file=sys.stderr, flush=True)
            self._free_run(int((now - self.last_sync_time) / period) - 1, apply_valves=False)
            self._free_run_next = now + period
        elif self.sync_lost_reported and self._free_run_next is not None and now >= self._free_run_next:
            steps = int((now - self._free_run_next) / period) + 1
            self._free_run(min(steps, FREE_RUN_CATCH_UP_STEPS))
            self._free_run_next += steps * period
        wait = self.next_heartbeat - now
        if self.last_sync_time is not None and not self.sync_lost_reported:
            wait = min(wait, self.last_sync_time + limit - now)
        elif self._free_run_next is not None:
            wait = min(wait, self._free_run_next - now)
        return max(wait, 0.0)

    def _free_run(self, steps: int, apply_valves: bool = True) -> None:
        """`steps` periods of physics without SYNC, the valves' spools as they are now (or,
        `apply_valves` False, the rig's commands as they were); the truth after each (the
        sensor nodes stay quiet: they sample on SYNC)."""
        for _ in range(max(steps, 0)):
            if apply_valves:
                self._apply_valves()
            self.rig.advance(self.cfg.nodes.sync_period_s)
            self._check_plant()
            self.counters.free_run_steps += 1
            self._send_truth(self.sync_counter)

    # -- receive ------------------------------------------------------------------------------
    def handle(self, msg: can.Message) -> None:
        self.counters.frames_in += 1
        status = self.decoder.receive_message(msg)
        frame_id = msg.arbitration_id
        if status is RxStatus.UNKNOWN_ID:
            self.counters.unknown_frames += 1
            return
        if frame_id == self._ids["SYNC"]:
            if status is RxStatus.OK:
                # how long the SYNC waited in the socket (kernel receive stamp): a node's
                # hardware starts its watchdog when the frame is on the bus, not when this
                # process gets round to it. Recorded for the trip reports only: timing the
                # watchdog from it trips the valves whenever this process falls behind (babble)
                waited = time.time() - msg.timestamp if msg.timestamp else 0.0
                self.on_sync(int(self.decoder.values["SYNC"][0]),
                             waited_s=min(max(waited, 0.0), self.cfg.nodes.sync_period_s))
            return
        if frame_id == self._ids["NMT"]:
            if status is RxStatus.OK:
                command, node = (int(v) for v in self.decoder.values["NMT"])
                self._nmt(command, node)
            return
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                self.counters.e2e_errors += 1
                node = self._cmd_slot.get(frame_id)
                if node is not None and status is not RxStatus.REPEATED:
                    self.valves[node].receive_invalid()
            return
        node = self._cmd_slot.get(frame_id)
        if node is not None:
            if self._ignore_commands or self.nmt[node] != NmtState.OPERATIONAL:
                return
            _, _, d, h, m, r, setpoint = self.decoder.values[f"VALVE_CMD_{node}"]
            self.valves[node].receive(bool(d), bool(h), bool(m), bool(r), float(setpoint))
        elif frame_id == self._ids["EMU_CTRL"]:
            self._emu_ctrl(*(self.decoder.values["EMU_CTRL"][2:]))
        elif frame_id == self._ids["EMU_KICK"]:
            self._kick(*(self.decoder.values["EMU_KICK"][2:]))

    def _kick(self, axis: float, value: float, duration_s: float) -> None:
        if not hasattr(self.rig, "kick"):
            print("emulator: EMU_KICK ignored: the test bench has no platform to push", file=sys.stderr, flush=True)
            return
        self.rig.kick(int(axis), float(value), float(duration_s))
        self.counters.kicks += 1

    def _nmt(self, command: int, node: int) -> None:
        if command == NmtCommand.START:      # the NMT master (re)started: its alive counters start afresh
            self.decoder.restart_sender(CODECS["NMT"].schedule.sender)
        targets = self.nodes if node == 0 else [node] if node in self.nmt else []
        for n in targets:
            if command == NmtCommand.START:
                self.nmt[n] = NmtState.OPERATIONAL
            elif command == NmtCommand.STOP:
                self.nmt[n] = NmtState.STOPPED
            elif command == NmtCommand.ENTER_PREOPERATIONAL:
                self.nmt[n] = NmtState.PRE_OPERATIONAL
            elif command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
                if command == NmtCommand.RESET_NODE and n in self.valves:
                    self.valves[n] = self._new_valve()
                    self.valves[n].boot()
                self.nmt[n] = NmtState.BOOTUP
                self._heartbeat(n)
                self.nmt[n] = NmtState.PRE_OPERATIONAL

    def _emu_ctrl(self, command: float, target: float, kind: float, load_kg: float, param: float) -> None:
        command, target, kind, param = int(command), int(target), int(kind), int(param)
        if command == EmuCommand.SET_LOAD:
            self.rig.set_load(load_kg)
        elif command == EmuCommand.INJECT_FAULT and kind in KNOWN_FAULTS:
            kind = EmuFault(kind)
            lasts = param if param > 0 and kind not in VALUE_PARAM_FAULTS else -1
            self.faults[(target, kind)] = [lasts, param]
            self.counters.injected[kind.name] = self.counters.injected.get(kind.name, 0) + 1
            self._apply_state_fault(target, kind, True)
            self._onsets.append({"target": target, "fault": kind.name})
        elif command == EmuCommand.CLEAR_FAULT:
            if self.faults.pop((target, kind), None) is not None:
                self._apply_state_fault(target, kind, False)
        elif command == EmuCommand.CLEAR_ALL:
            for key in list(self.faults):
                self.faults.pop(key)
                self._apply_state_fault(*key, False)

    def _apply_state_fault(self, target: int, kind: int, on: bool) -> None:
        if not on:
            self._onset_values.pop((target, kind), None)
        if kind == EmuFault.VALVE_JAM and 1 <= target <= self.rig.n_legs:
            self.rig.jammed[target - 1] = on
        elif kind == EmuFault.LEG_JAM and 1 <= target <= self.rig.n_legs:
            self.rig.set_rod_seized(target - 1, on)
        elif kind == EmuFault.SEAL_LEAK and 1 <= target <= self.rig.n_legs:
            self.rig.set_seal_leak(target - 1, float(self.faults[(target, kind)][1]) if on else 0.0)
        elif kind == EmuFault.REPEAT and not on:
            self._last_sent.clear()
        elif kind in (EmuFault.SUPPLY_LOSS, EmuFault.SUPPLY_DROP):
            self.rig.set_supply_fraction(self._supply_fraction())
        elif kind == EmuFault.DROP and target == CONTROLLER_NODE:
            self._ignore_commands = on
        elif kind == EmuFault.DELAY and not on:
            self._flush_delayed()

    def _supply_fraction(self) -> float:
        """The power unit's share of its nominal pressure under the supply faults injected:
        none with SUPPLY_LOSS (it stops), SUPPLY_DROP's percentage, else all."""
        if any(kind == EmuFault.SUPPLY_LOSS for _, kind in self.faults):
            return 0.0
        drops = [entry[1] for (_, kind), entry in self.faults.items() if kind == EmuFault.SUPPLY_DROP]
        return min(drops) / 100.0 if drops else 1.0

    def _flush_delayed(self) -> None:
        delayed, self._delayed = self._delayed, []
        for message in delayed:
            self._send(message)

    # -- SYNC ---------------------------------------------------------------------------------
    def on_sync(self, counter: int, waited_s: float = 0.0) -> None:
        now = self.clock()
        phase = self.phase_s[self.counters.syncs % SYNC_HISTORY]
        self.counters.syncs += 1
        if self.sync_counter and counter != self.sync_counter % self._overflow + 1:
            self.counters.sync_sequence_errors += 1
        self.sync_counter = counter
        self.last_sync_time = now
        self.last_sync_waited_s = waited_s
        self.sync_lost_reported = False
        self._free_run_next = None
        self._flush_delayed()
        for n, valve in self.valves.items():
            if self.nmt[n] != NmtState.OPERATIONAL:
                continue
            emergency = valve.on_sync()
            if emergency is None:
                emergency = valve.check_spool(float(self.rig.state[n - 1, hy.S_SPOOL]), float(self.spool_demand[n - 1]))
            if emergency is not None:
                self._emergency(n, emergency)
        nodes = self.clock()
        self._sample_and_send(counter)
        sent = self.clock()
        self._apply_valves()
        self.rig.advance(self.cfg.nodes.sync_period_s)
        stepped = self.clock()
        self._check_plant()
        self._count_down_faults()
        phase[SP_RESPONSE], phase[SP_NODES], phase[SP_SEND] = sent - now, nodes - now, sent - nodes
        phase[SP_PHYSICS], phase[SP_TOTAL] = stepped - sent, self.clock() - now
        if self._onsets:                          # after the response: a print takes its time
            self._report_onsets(counter)

    def _check_plant(self) -> None:
        """Say once, on stderr, that the emulated physics diverged; count every such period."""
        rig, counters = self.rig, self.counters
        if rig.unstable_periods == counters.plant_unstable:
            return
        if counters.plant_unstable == 0:
            print(f"emulator: the emulated plant diverged at t = {rig.first_unstable_s:.3f} s (MuJoCo reset it, or a "
                  "state not finite): what follows is not physics", file=sys.stderr, flush=True)
        counters.plant_unstable = rig.unstable_periods
        counters.plant_unstable_first_s = rig.first_unstable_s

    def _report_onsets(self, counter: int) -> None:
        for onset in self._onsets:
            onset |= {"sync_counter": counter, "t_epoch_s": time.time()}
            self.counters.fault_onsets.append(onset)
            print(f"{FAULT_ONSET_EVENT} {json.dumps(onset)}", file=sys.stderr, flush=True)
        self._onsets.clear()

    def _apply_valves(self) -> None:
        """Spool commands to the rig, and the load-holding valves open only while ACTIVE."""
        blocks = self.cfg.nodes.hold_blocks_ports
        for n, valve in self.valves.items():
            stuck = self._fault(n, EmuFault.SPOOL_STUCK)        # the spool goes there whatever its demand
            self.spool_demand[n - 1] = valve.spool_command
            self.rig.command[n - 1] = valve.spool_command if stuck is None else stuck[1] / 100.0
            self.rig.ports_open[n - 1] = 0.0 if blocks and valve.state is not ValveState.ACTIVE else 1.0

    def _count_down_faults(self) -> None:
        for key, entry in list(self.faults.items()):
            if key[1] == EmuFault.BABBLE:
                babble = can.Message(arbitration_id=BABBLE_ID, data=bytes(8), is_extended_id=False)
                for _ in range(max(entry[1], 1)):
                    self._send(babble)
            if entry[0] > 0:
                entry[0] -= 1
                if entry[0] == 0:
                    del self.faults[key]
                    self._apply_state_fault(*key, False)

    def _due(self, name: str, counter: int) -> bool:
        period = self._period.get(name, 0)
        if period <= 1:
            return period == 1
        return (counter - 1) % period == CODECS[name].schedule.sync_phase % period

    def _sample_and_send(self, counter: int) -> None:
        rig, cfg, rng = self.rig, self.cfg, self.rng
        if self.has_imu and self.nmt[IMU_NODE] == NmtState.OPERATIONAL:
            if self._due("IMU_ATTITUDE", counter):
                _, quat = rig.platform_pose()
                box = self.out["IMU_ATTITUDE"]
                box.values[box.index["ROLL"]:box.index["YAW"] + 1] = (
                    attitude_rpy(quat) + cfg.sensors.imu_angle_noise_rad * rng.standard_normal(3))
                self._emit(IMU_NODE, "IMU_ATTITUDE")
            if self._due("IMU_RATE", counter):
                box = self.out["IMU_RATE"]
                rate = rig.platform_body_rate() + cfg.sensors.imu_rate_noise_rad_s * rng.standard_normal(3)
                box.values[box.index["RATE_X"]:box.index["RATE_Z"] + 1] = rate
                self._emit(IMU_NODE, "IMU_RATE")
        for n in self.legs:
            if self.nmt[n] != NmtState.OPERATIONAL:
                continue
            i = n - 1
            valve = self.valves[n]
            measured = rig.state[i, hy.S_Y]
            drift = self._fault(n, EmuFault.ENCODER_DRIFT)
            if drift is not None:                      # um/s since the fault's onset, read in counts too
                start = self._onset_values.setdefault((n, EmuFault.ENCODER_DRIFT), rig.time_s)
                measured += drift[1] * 1e-6 * (rig.time_s - start)
            position = round(measured / cfg.sensors.encoder_resolution_m) * cfg.sensors.encoder_resolution_m
            force = rig.rod_force_n[i] + cfg.sensors.load_cell_noise_n * rng.standard_normal()
            if self._fault(n, EmuFault.STUCK):
                position, force = self._onset_values.setdefault((n, EmuFault.STUCK), (position, force))
            if self._fault(n, EmuFault.FORCE_STUCK):
                force = self._onset_values.setdefault((n, EmuFault.FORCE_STUCK), force)
            if self._fault(n, EmuFault.FORCE_ZERO):
                force = 0.0
            if self._fault(n, EmuFault.OUT_OF_RANGE):
                param = self.faults[(n, EmuFault.OUT_OF_RANGE)][1]
                force = float(param) if param else 1e9         # saturates at the DBC's maximum
            name = f"LEG_PRESSURE_{n}"
            if self._due(name, counter):
                box = self.out[name]
                noise = cfg.sensors.pressure_noise_pa
                box.values[box.index["PA"]] = rig.state[i, hy.S_PA] + noise * rng.standard_normal()
                box.values[box.index["PB"]] = rig.state[i, hy.S_PB] + noise * rng.standard_normal()
                box.values[box.index["PS"]] = rig.supply_pressure_pa + noise * rng.standard_normal()
                self._emit(n, name)
            name = f"VALVE_STATUS_{n}"
            if self._due(name, counter):
                box = self.out[name]
                box.values[box.index["VALVE_STATE"]] = int(valve.state)
                box.values[box.index["SPOOL_ACTUAL"]] = rig.state[i, hy.S_SPOOL]
                box.values[box.index["FAULT_REASON"]] = int(valve.fault_reason)
                self._emit(n, name)
            box = self.out[f"LEG_STATE_{n}"]
            box.values[box.index["VALVE_STATE"]] = int(valve.state)
            box.values[box.index["SENSOR_FAULT"]] = 0
            box.values[box.index["POSITION"]] = position
            box.values[box.index["FORCE"]] = force
            box.values[box.index["SPOOL"]] = rig.state[i, hy.S_SPOOL]
            self._emit(n, box.codec.name)
        self._send_truth(counter)

    def _send_truth(self, counter: int) -> None:
        """EMU_TRUTH: the simulated pose for HIL metrics (after the leg frames: the
        controller's collection never waits for it)."""
        box = self.out["EMU_TRUTH"]
        box.values[box.index["SYNC_PHASE"]] = counter % 16
        if self.has_imu:
            position, _ = self.rig.platform_pose()
            for axis, value in zip("XYZ", position):
                box.values[box.index[axis]] = value
        else:
            box.values[box.index["Z"]] = self.rig.state[0, hy.S_Y]
        self._emit(0, "EMU_TRUTH")

    # -- process loop -------------------------------------------------------------------------
    def pause_node_clocks(self, seconds: float) -> None:
        """The emulated nodes' timers stand still for `seconds` (this process was not running).

        A real valve's SYNC watchdog is a hardware timer; ours is this process's wall clock.
        When the whole host stalls (measured here with a SCHED_FIFO sleeper on each CPU: 3-10 ms
        late wake-ups, mostly on both CPUs at once, a few per minute) the controller cannot send
        SYNC and we cannot watch for it either; a freeze longer than the watchdog would read as
        a lost SYNC and fault the valves. A controller that stalls alone still trips it.
        """
        self.counters.host_stalls += 1
        self.counters.host_stall_max_s = max(self.counters.host_stall_max_s, seconds)
        if self.last_sync_time is not None:
            self.last_sync_time += seconds
        if self._free_run_next is not None:
            self._free_run_next += seconds
        self.next_heartbeat += seconds

    def run(self, should_stop) -> None:
        """Receive and dispatch until `should_stop()`; timers between frames."""
        self.boot()
        wait = 0.0
        while not should_stop():
            timeout = min(max(wait, 0.0005), 0.05)
            wake = self.clock() + timeout
            msg = self.bus.recv(timeout=timeout)
            received = self.clock()
            if received - wake > self.cfg.nodes.sync_period_s:         # woken this late: not scheduled
                self.pause_node_clocks(received - wake)
            if msg is not None:
                self.handle(msg)
                busy = self.clock() - received
                if busy > self.cfg.nodes.sync_period_s:                # a stall inside the handling
                    self.pause_node_clocks(busy)
            wait = self.poll()

    def summary(self) -> dict:
        valves = {str(n): ValveState(v.state).name for n, v in self.valves.items()}
        n = min(self.counters.syncs, SYNC_HISTORY)
        phases = {name: percentiles_us(self.phase_s[:n, j]) for j, name in enumerate(SYNC_PHASES)} if n else {}
        return {"rig": self.rig.name, "sim_time_s": round(self.rig.time_s, 6), **self.counters.as_dict(),
                "phases_us": phases,
                "rx_status": {s.name: int(c) for s, c in zip(RxStatus, self.decoder.counts.sum(axis=0))},
                "valves": valves}
