"""The emulated rig's nodes on the bus: each leg's node (CiA 408 valve driver with the leg's
encoder, load cell and pressure transducers), the IMU node (hexapod), NMT, heartbeats, EMCY,
the SYNC watchdog, and the injected frame faults. The rig behind them, its valves and its
sensors are `simulated_rig.SimulatedRig`; this module only puts it on the bus.

Per SYNC k (docs/ARCHITECTURE.md "The emulator's cycle"):
1. every OPERATIONAL valve applies the command latched during cycle k-1 and checks its spool
   (EMCY on a fault);
2. every OPERATIONAL sensor node samples the rig as it is at t_k and sends its frames due on
   this SYNC (LEG_STATE every SYNC, with the valve state just applied; LEG_PRESSURE,
   VALVE_STATUS, IMU at their divisors), the IMU's first and each leg's LEG_STATE last: the
   controller closes its window on the LEG_STATEs, and one socket keeps this order, so the
   samples of SYNC k it uses are those of cycle k, never by chance the next cycle's;
3. the rig integrates exactly one SYNC period with the applied spool setpoints.
So the emulator follows whoever produces SYNC, in realtime and lockstep pacing alike.
Heartbeats and the SYNC-loss watchdog run on the clock (`poll`), like a real node's timers.
When the watchdog trips (the controller died or stalled), the plant does not stop with the
bus: the physics catches up to the trip with the valves as they were, then runs on the
clock with the valves in FAULT_HOLD, and EMU_TRUTH reports where the mechanism went (what a
fault test measures), until SYNC returns. The process around it: `process.py`.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field

import can
import numpy as np

from plant_emulator.canopen_nodes import CanopenNodes
from plant_emulator.devices import EmulatedDevices
from plant_emulator.injected import KNOWN_FAULTS
from plant_emulator.params import EmulatorConfig
from plant_emulator.simulated_rig import SimulatedRig
from plant_emulator.valve_node import Emergency, ValveState
from program.realtime import percentiles_us
from protocol.canopen_layout import LAYOUT_FILE
from protocol.codec import CODECS, STANDARD_ID_MASK, FrameDecoder
from protocol.dbc import sync_counter_overflow, truth_phase
from protocol.devices import DEVICE_PROFILES, EMCY_BASE
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.enums import EmuCommand, EmuFault, NmtCommand, NmtState, Pacing
from protocol.interfaces import attitude_values, leg_pressure_values, leg_state_values, rate_values, valve_command_of
from protocol.nodes import CONTROLLER_NODE, IMU_NODE, rig_nodes
from protocol.outbox import Outbox

# per SYNC (seconds each, `phase_s`): from the SYNC's handling to the last sampled frame sent;
# the valve nodes' SYNC handling; sampling, encoding and sending; the physics step; the whole
SYNC_PHASES = ("response", "nodes", "send", "physics", "total")
SP_RESPONSE, SP_NODES, SP_SEND, SP_PHYSICS, SP_TOTAL = range(len(SYNC_PHASES))
SYNC_HISTORY = 1 << 16
BABBLE_ID = 0x601                    # not in the DBC (an SDO request id of node 1)
NO_COMMAND_TIMEOUT = 1 << 62          # a stock valve whose RPDO timeout is 0: never times out
FREE_RUN_CATCH_UP_STEPS = 25         # free run: periods of physics per poll at most (a late wake-up)
SYNC_TIMEOUT_EVENT = "emulator: event sync_timeout"   # a stderr line per SYNC-watchdog trip (JSON after it)
# a stderr line per injected fault, at the first SYNC that sees it: the fault's onset cycle
# (the host's EMU_CTRL and the controller's SYNC race to this process: only it knows the order)
FAULT_ONSET_EVENT = "emulator: event fault_onset"


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
    joint_limits: int = 0             # periods that ended with a universal joint on its stop
    joint_limits_first_s: float | None = None       # the simulated time of the first of them
    # every SYNC-watchdog trip: when (epoch s), and how late this process woke for it (ms): a
    # real node's hardware timer fires on time; ours is this process's wake-up (hil faults, case 1)
    sync_timeouts: list = field(default_factory=list)
    fault_onsets: list = field(default_factory=list)    # every injection: its SYNC counter and epoch time

    def as_dict(self, injected: dict) -> dict:
        return {k: getattr(self, k) for k in ("syncs", "frames_in", "frames_out", "e2e_errors",
                                              "sync_sequence_errors", "valve_faults", "emergencies",
                                              "unknown_frames", "host_stalls", "free_run_steps",
                                              "kicks", "plant_unstable", "plant_unstable_first_s", "joint_limits",
                                              "joint_limits_first_s")} | {
            "host_stall_max_ms": round(self.host_stall_max_s * 1e3, 3), "injected": dict(injected),
            "sync_timeouts": list(self.sync_timeouts), "fault_onsets": list(self.fault_onsets)}


class Emulator:
    """Nodes of one rig on one bus. `handle(msg)` for every received frame, `poll(now)` often."""

    def __init__(self, bus: can.BusABC | None, rig, cfg: EmulatorConfig, clock=time.monotonic,
                 pacing: str | None = None, devices: str = "hydrapod", layout=LAYOUT_FILE):
        self.bus, self.rig, self.cfg, self.clock = bus, rig, cfg, clock
        # its own --pacing, said against the controller's CTRL_STATUS.PACING (None: not checked)
        self.pacing = Pacing[pacing.upper()] if pacing is not None else None
        self.controller_pacing: Pacing | None = None
        self.sim = SimulatedRig(rig, cfg)
        self.legs = range(1, rig.n_legs + 1)
        self.has_imu = self.sim.has_imu
        if devices not in DEVICE_PROFILES:
            raise ValueError(f"devices must be one of {', '.join(DEVICE_PROFILES)}, got {devices!r}")
        # the stock CANopen devices (canopen_nodes.py), or the project's own leg and IMU nodes
        self.canopen = CanopenNodes(rig.n_legs, self._send, layout) if devices == "canopen" else None
        self.nodes = self.canopen.nodes if self.canopen is not None else rig_nodes(rig.n_legs)
        self.nmt = {n: NmtState.BOOTUP for n in self.nodes}
        names = ["NMT", "SYNC", "EMU_CTRL", "EMU_KICK", "CTRL_STATUS"]
        if self.canopen is None:                 # the valves' VALVE_CMD ids are CANopen's RPDO1s
            names += [f"VALVE_CMD_{n}" for n in self.legs]
        self.decoder = FrameDecoder(names)
        self._cmd_slot = {CODECS[f"VALVE_CMD_{n}"].frame_id: n for n in self.legs} if self.canopen is None else {}
        self._ids = {name: CODECS[name].frame_id for name in names}
        self._pacing_index = CODECS["CTRL_STATUS"].index["PACING"]
        self.out = {name: Outbox(name) for name in self._tx_names()}
        # each leg's valve node (the DBC profile's leg node); its EMCY on that node's id
        self.valve_node = dict(self.canopen.valve_node) if self.canopen is not None else {n: n for n in self.legs}
        self._leg_of_valve = {node: leg for leg, node in self.valve_node.items()}
        for leg, node in self.valve_node.items():
            self.out[f"EMCY_{leg}"].message.arbitration_id = EMCY_BASE + node
        self.counters = Counters()
        self.sync_counter = 0
        self.last_sync_time: float | None = None
        self.last_sync_waited_s = 0.0          # how long that SYNC sat in the socket first
        self.sync_lost_reported = False
        self.next_heartbeat = 0.0                 # the earliest of the nodes' next heartbeats
        self._beat_period: dict[int, float] = {}
        self._next_beat: dict[int, float] = {}
        self._held: dict[str, bytes] = {}                  # REORDER: frame held back per message
        self._last_sent: dict[str, bytes] = {}             # REPEAT: the frame sent before the fault
        self._free_run_next: float | None = None           # wall time of the next free-run step
        self._delayed: list[can.Message] = []              # DELAY: frames sent at the next SYNC
        self._onsets: list[dict] = []                      # injected since the last SYNC
        self._leg_operational = np.zeros(rig.n_legs, dtype=bool)
        self._leg_sensing = np.zeros(rig.n_legs, dtype=bool)         # a leg's stock devices: any OPERATIONAL
        self._overflow = sync_counter_overflow()
        self.phase_s = np.zeros((SYNC_HISTORY, len(SYNC_PHASES)))     # per SYNC, seconds
        self.devices = self.canopen.sdo if self.canopen is not None else EmulatedDevices(
            {n: cfg.nodes.imu_eds if n == IMU_NODE else cfg.nodes.leg_eds for n in self.nodes}, self._send)

    @property
    def valves(self) -> dict:
        """Each leg node's valve driver, by node id."""
        return {n: self.sim.valves[n - 1] for n in self.legs}

    @property
    def faults(self):
        return self.sim.faults

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
        return self.sim.faults.get(target, kind)

    def _emit(self, node: int, name: str) -> None:
        """Encode and send a node's frame through the injected frame faults."""
        box = self.out[name]
        if box.encode():
            self.emit_frame(node, name, box.message)

    def emit_frame(self, node: int, name: str, message: can.Message) -> None:
        """Send frame `name` of `node` (the DBC's node id: a leg's, the IMU's) through the
        injected frame faults (a stock device's frames: those of its leg's node id)."""
        if not self.sim.faults:                # the common case: nothing injected
            self._last_sent[name] = bytes(message.data)
            self._send(message)
            return
        if self.sim.silent(node):
            return
        loss = self._fault(node, EmuFault.FRAME_LOSS)
        if loss is not None and self.sim.sensors.rng.random() * 100.0 < loss[1]:
            return
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

    def _emergency(self, leg: int, emergency: Emergency) -> None:
        """Leg `leg`'s valve says `emergency` (EMCY on its valve node's id)."""
        box = self.out[f"EMCY_{leg}"]
        box.values[:] = (emergency.error_code, emergency.error_register, int(emergency.state),
                         int(emergency.reason), self.sync_counter % 256, emergency.info)
        self.counters.emergencies += 1
        if emergency.error_code:
            self.counters.valve_faults += 1
        if not self._fault(self.valve_node[leg], EmuFault.SILENT) and box.encode():
            self._send(box.message)

    def _heartbeat(self, node: int) -> None:
        if self.canopen is not None:
            if not self._fault(node, EmuFault.SILENT):
                self._send(self.canopen.heartbeat(node, self.nmt[node]))
            return
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
        self.sim.boot()
        for n in self.nodes:
            self.nmt[n] = NmtState.BOOTUP
        self._heartbeats()
        for n in self.nodes:
            self.nmt[n] = NmtState.PRE_OPERATIONAL
            if self.cfg.nodes.nmt_autostart:
                self._start(n)
        now = self.clock()
        self._beat_period = {n: self._heartbeat_period(n) for n in self.nodes}
        self._next_beat = {n: now + period for n, period in self._beat_period.items()}
        self.next_heartbeat = min(self._next_beat.values())

    def _heartbeat_period(self, node: int) -> float:
        """A node's heartbeat producer time, s (inf: it sends none): a stock device's 0x1017."""
        period = self.canopen.heartbeat_s(node) if self.canopen is not None else self.cfg.nodes.heartbeat_s
        return period if period > 0 else math.inf

    def _heartbeat_changed(self, node: int) -> None:
        """The node's heartbeat producer time written (SDO) or reset: it beats on the new one."""
        period = self._heartbeat_period(node)
        if period != self._beat_period[node]:
            self._beat_period[node] = period
            self._next_beat[node] = self.clock() + period
            self.next_heartbeat = min(self._next_beat.values())

    def poll(self, now: float | None = None) -> float:
        """Timers: heartbeats and the SYNC watchdog. Returns seconds until the next timer."""
        now = self.clock() if now is None else now
        if now >= self.next_heartbeat:
            for n, due in self._next_beat.items():
                if now >= due:
                    self._heartbeat(n)
                    self._next_beat[n] = now + self._beat_period[n]
            self.next_heartbeat = min(self._next_beat.values())
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
        for n in self._next_beat:
            self._next_beat[n] += seconds

    def _free_run(self, steps: int, apply_valves: bool = True) -> None:
        """`steps` periods of physics without SYNC, the valves' spools as they are now (or,
        `apply_valves` False, the rig's commands as they were); the truth after each (the
        sensor nodes stay quiet: they sample on SYNC)."""
        for _ in range(max(steps, 0)):
            if apply_valves:
                self.sim.apply_valves()
            self.sim.advance()
            self._check_plant()
            self.counters.free_run_steps += 1
            self._send_truth(self.sync_counter)

    # -- receive ------------------------------------------------------------------------------
    def can_filters(self) -> list[dict]:
        """The nodes' CAN controllers' acceptance filters: the DBC's frames they take, and SDO."""
        filters = self.decoder.can_filters() + self.devices.can_filters()
        if self.canopen is not None:
            filters += [{"can_id": frame_id, "can_mask": STANDARD_ID_MASK, "extended": False}
                        for frame_id in self.canopen.rpdo_ids()]
        return filters

    def handle(self, msg: can.Message) -> None:
        self.counters.frames_in += 1
        node = self.devices.node_of(msg.arbitration_id)
        if node is not None:                  # SDO: served in every NMT state but STOPPED (CiA 301)
            if self.nmt[node] != NmtState.STOPPED and not self._fault(node, EmuFault.SILENT):
                self.devices.answer(msg)
                if self.canopen is not None and node in self._beat_period:
                    self._heartbeat_changed(node)
            return
        if self.canopen is not None and msg.arbitration_id in self.canopen.rpdo_of:
            if not self._fault(CONTROLLER_NODE, EmuFault.DROP):
                self.canopen.receive_rpdo(msg.arbitration_id, msg.data, self.sim.valves, self._operational)
            return
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
        if frame_id == self._ids["CTRL_STATUS"]:
            if status is RxStatus.OK:
                self._controller_status()
            return
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                self.counters.e2e_errors += 1
                node = self._cmd_slot.get(frame_id)
                if node is not None and status is not RxStatus.REPEATED:
                    self.sim.valves[node - 1].receive_invalid()
            return
        node = self._cmd_slot.get(frame_id)
        if node is not None:
            if self._fault(CONTROLLER_NODE, EmuFault.DROP) or self.nmt[node] != NmtState.OPERATIONAL:
                return
            self.sim.valves[node - 1].receive(*valve_command_of(self.decoder.values[f"VALVE_CMD_{node}"]))
        elif frame_id == self._ids["EMU_CTRL"]:
            self._emu_ctrl(*(self.decoder.values["EMU_CTRL"][2:]))
        elif frame_id == self._ids["EMU_KICK"]:
            self._kick(*(self.decoder.values["EMU_KICK"][2:]))

    def _controller_status(self) -> None:
        """Say once, on stderr, that the controller runs another pacing than this process."""
        pacing = Pacing(int(self.decoder.values["CTRL_STATUS"][self._pacing_index]))
        if pacing is not self.controller_pacing and self.pacing is not None and pacing is not self.pacing:
            print(f"emulator: the controller runs --pacing {pacing.name.lower()}, this emulator --pacing "
                  f"{self.pacing.name.lower()}: start both with the same --pacing", file=sys.stderr, flush=True)
        self.controller_pacing = pacing

    def _kick(self, axis: float, value: float, duration_s: float) -> None:
        if not hasattr(self.rig, "kick"):
            print("emulator: EMU_KICK ignored: the test bench has no platform to push", file=sys.stderr, flush=True)
            return
        self.rig.kick(int(axis), float(value), float(duration_s))
        self.counters.kicks += 1

    def _slide(self, command) -> None:
        """Appendix D's free falls: the test bench's slide unbolted from the rod, or bolted again
        (only where it rests on the rod's tip)."""
        if not hasattr(self.rig, "unbolt_slide"):
            print(f"emulator: EMU_CTRL {command.name} ignored: the hexapod has no guide", file=sys.stderr, flush=True)
        elif command == EmuCommand.UNBOLT_SLIDE:
            self.rig.unbolt_slide()
        elif not self.rig.bolt_slide():
            print(f"emulator: EMU_CTRL BOLT_SLIDE ignored: the slide is {1e3 * self.rig.gap_m:.1f} mm above the rod",
                  file=sys.stderr, flush=True)

    def _nmt(self, command: int, node: int) -> None:
        if command == NmtCommand.START:      # the NMT master (re)started: its alive counters start afresh
            self.decoder.restart_sender(CODECS["NMT"].schedule.sender)
        targets = self.nodes if node == 0 else [node] if node in self.nmt else []
        for n in targets:
            if command == NmtCommand.START:
                self._start(n)
            elif command == NmtCommand.STOP:
                self.nmt[n] = NmtState.STOPPED
            elif command == NmtCommand.ENTER_PREOPERATIONAL:
                self.nmt[n] = NmtState.PRE_OPERATIONAL
            elif command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
                leg = self._leg_of_valve.get(n)
                if command == NmtCommand.RESET_NODE and leg is not None:
                    self.sim.valves[leg - 1] = self.sim.new_valve()
                    self.sim.valves[leg - 1].boot()
                if self.canopen is not None:          # a stock device forgets what a master wrote
                    self.canopen.reset(n)
                    if n in self._beat_period:
                        self._heartbeat_changed(n)
                self.nmt[n] = NmtState.BOOTUP
                self._heartbeat(n)
                self.nmt[n] = NmtState.PRE_OPERATIONAL

    def _start(self, node: int) -> None:
        """NMT start: OPERATIONAL, a stock device only with PDOs it can carry; a stock valve's
        command timeout is its RPDO timeout as written (0x1400:5), in SYNC periods."""
        if self.canopen is not None:
            if not self.canopen.start(node):
                return
            leg = self._leg_of_valve.get(node)
            if leg is not None:
                timeout_ms = self.canopen.rpdo_timeout_ms(node)
                period_ms = self.cfg.nodes.sync_period_s * 1e3
                self.sim.valves[leg - 1].command_timeout_syncs = (
                    math.ceil(timeout_ms / period_ms - 1e-9) if timeout_ms else NO_COMMAND_TIMEOUT)
        self.nmt[node] = NmtState.OPERATIONAL

    def _operational(self, node: int) -> bool:
        return self.nmt[node] == NmtState.OPERATIONAL

    def _emu_ctrl(self, command: float, target: float, kind: float, load_kg: float, param: float) -> None:
        command, target, kind, param = int(command), int(target), int(kind), int(param)
        if command == EmuCommand.SET_LOAD:
            self.rig.set_load(load_kg)
        elif command in (EmuCommand.UNBOLT_SLIDE, EmuCommand.BOLT_SLIDE):
            self._slide(EmuCommand(command))
        elif command == EmuCommand.INJECT_FAULT and kind in KNOWN_FAULTS:
            self.inject(target, EmuFault(kind), param)
        elif command == EmuCommand.CLEAR_FAULT:
            if self.sim.clear(target, kind):
                self._frames_fault_ended(target, kind)
        elif command == EmuCommand.CLEAR_ALL:
            for key in self.sim.clear_all():
                self._frames_fault_ended(*key)

    def inject(self, target: int, kind: EmuFault, param: int) -> None:
        """A fault on node `target` (EMU_CTRL INJECT_FAULT); its onset is reported at the next SYNC."""
        self.sim.inject(target, kind, param)
        self._onsets.append({"target": target, "fault": kind.name})

    def _frames_fault_ended(self, target: int, kind: int) -> None:
        """What a frame fault leaves behind when it ends."""
        if kind == EmuFault.REPEAT:
            self._last_sent.clear()
        elif kind == EmuFault.DELAY:
            self._flush_delayed()

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
        sim = self.sim
        for i, n in enumerate(self.legs):
            self._leg_operational[i] = self.nmt[self.valve_node[n]] == NmtState.OPERATIONAL
        sensing = self._leg_operational
        if self.canopen is not None:              # a leg's encoder and measuring device are nodes of their own
            for i, n in enumerate(self.legs):
                self._leg_sensing[i] = any(self._operational(node) for node in self.canopen.leg_nodes[n])
            sensing = self._leg_sensing
        for i, emergency in sim.valves_on_sync(self._leg_operational):
            self._emergency(i + 1, emergency)
        nodes = self.clock()
        sim.sample(counter, sensing, self.has_imu and self.nmt[IMU_NODE] == NmtState.OPERATIONAL)
        self._send_samples()
        sent = self.clock()
        sim.apply_valves()
        sim.advance()
        stepped = self.clock()
        self._check_plant()
        for key in sim.end_sync():
            self._frames_fault_ended(*key)
        self._babble()
        phase[SP_RESPONSE], phase[SP_NODES], phase[SP_SEND] = sent - now, nodes - now, sent - nodes
        phase[SP_PHYSICS], phase[SP_TOTAL] = stepped - sent, self.clock() - now
        if self._onsets:                          # after the response: a print takes its time
            self._report_onsets(counter)

    def _babble(self) -> None:
        """BABBLE: frames of an id not in the DBC, FAULT_PARAM of them per SYNC."""
        for count in self.sim.faults.of_kind(EmuFault.BABBLE):
            babble = can.Message(arbitration_id=BABBLE_ID, data=bytes(8), is_extended_id=False)
            for _ in range(max(count, 1)):
                self._send(babble)

    def _send_samples(self) -> None:
        """This SYNC's samples as frames: the IMU's first, each leg's LEG_STATE last."""
        sim = self.sim
        if self.canopen is not None:
            self.canopen.send_tpdos(self.sync_counter, sim, self._operational, self.emit_frame)
            self._send_truth(self.sync_counter)
            return
        if sim.attitude_due:
            attitude_values(self.out["IMU_ATTITUDE"].values, sim.attitude_rad)
            self._emit(IMU_NODE, "IMU_ATTITUDE")
        if sim.rate_due:
            rate_values(self.out["IMU_RATE"].values, sim.rate_rad_s)
            self._emit(IMU_NODE, "IMU_RATE")
        for i, n in enumerate(self.legs):
            if not sim.sampled[i]:
                continue
            valve = sim.valves[i]
            if sim.pressure_due[i]:
                leg_pressure_values(self.out[f"LEG_PRESSURE_{n}"].values, *sim.pressure[i])
                self._emit(n, f"LEG_PRESSURE_{n}")
            if sim.status_due[i]:
                box = self.out[f"VALVE_STATUS_{n}"]
                box.values[box.index["VALVE_STATE"]] = int(valve.state)
                box.values[box.index["SPOOL_ACTUAL"]] = sim.spool_actual(i)
                box.values[box.index["FAULT_REASON"]] = int(valve.fault_reason)
                self._emit(n, f"VALVE_STATUS_{n}")
            leg_state_values(self.out[f"LEG_STATE_{n}"].values, sim.position_m[i], sim.force_n[i],
                             sim.spool_actual(i), int(valve.state), False)
            self._emit(n, f"LEG_STATE_{n}")
        self._send_truth(self.sync_counter)

    def _check_plant(self) -> None:
        """Say once, on stderr, that the emulated physics diverged, or that the platform went
        where the rig's joints stop it; count every such period."""
        rig, counters = self.rig, self.counters
        if rig.joint_limit_periods != counters.joint_limits:
            if counters.joint_limits == 0:
                print(f"emulator: a universal joint reached its stop at t = {rig.first_joint_limit_s:.3f} s (the "
                      "platform where the rig's joints stop it)", file=sys.stderr, flush=True)
            counters.joint_limits = rig.joint_limit_periods
            counters.joint_limits_first_s = rig.first_joint_limit_s
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

    def _send_truth(self, counter: int) -> None:
        """EMU_TRUTH: the simulated pose for HIL metrics (after the leg frames: the
        controller's collection never waits for it)."""
        box = self.out["EMU_TRUTH"]
        box.values[box.index["SYNC_PHASE"]] = truth_phase(counter)
        if self.has_imu:
            position, _ = self.rig.platform_pose()
            for axis, value in zip("XYZ", position):
                box.values[box.index[axis]] = value
        else:
            box.values[box.index["Z"]] = self.rig.stroke_m[0]
        self._emit(0, "EMU_TRUTH")

    def summary(self) -> dict:
        valves = {str(n): ValveState(v.state).name for n, v in self.valves.items()}
        n = min(self.counters.syncs, SYNC_HISTORY)
        phases = {name: percentiles_us(self.phase_s[:n, j]) for j, name in enumerate(SYNC_PHASES)} if n else {}
        pacings = {"pacing": self.pacing, "controller_pacing": self.controller_pacing}
        return {"rig": self.rig.name, "sim_time_s": round(self.rig.time_s, 6),
                **{k: p.name.lower() if p is not None else None for k, p in pacings.items()},
                **self.counters.as_dict(self.sim.faults.injected), "phases_us": phases,
                "rx_status": {s.name: int(c) for s, c in zip(RxStatus, self.decoder.counts.sum(axis=0))},
                "valves": valves}
