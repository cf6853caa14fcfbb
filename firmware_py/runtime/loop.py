"""The controller on the bus: lifecycle (configure -> activate -> run -> shut down) and the
fixed-step cycle SYNC -> collect -> read -> update -> write. The rig's devices sit behind a
hardware interface (`hardware.py`: the project's own nodes, `hardware_dbc.py`, or stock
CANopen devices, `hardware_canopen.py`, by `devices`); the loop owns the SYNC, the host's
frames and its own (CTRL_*, its heartbeat and EMCY).

configure (constructor): codecs compiled at import, every array and CAN message allocated.
activate: every node heard (its heartbeat), then identified by SDO (runtime/identify.py: a
node that is not the configured device is never started) and prepared (stock devices:
configured by SDO and read back), then NMT start (repeated until every node's heartbeat
says OPERATIONAL), then
`hold_cycles` cycles with the valves in HOLD (the first with a Reset pulse, clearing faults
left by an earlier session), then IDLE or READY (auto_enable).
cycle k: send SYNC k; collect the devices' samples of cycle k until all are in or the window
closes (realtime: a fraction of the period; lockstep: the emulator's EMU_TRUTH of that SYNC,
its last frame, or a timeout for a dead emulator); `read` fills the
Measurements; `Controller.update(meas, cmd)`; `write` puts the ValveCommands on the bus
(applied by the valves at SYNC k+1), CTRL_STATUS when due, CTRL_ACK for host
frames and the heartbeat when due; then the controller's host work that must not delay
the valves' commands (a waypoint commit).
The loop decides nothing: it records what it saw (frames, heartbeats, EMCY, a stall of its
own) and the controller's supervisor raises the faults, in the cycle they are seen.
pacing: `realtime` - absolute deadlines on the monotonic clock, sleep then spin, late
cycles counted as overruns and skipped (never bursts); a stall (the clock
`stall_fault_periods` past the last SYNC, seen after any wait) is reported to the next
update, which faults OVERRUN before acting on anything received meanwhile. With the bus's
SYNC (`runtime/sync.py`: on SocketCAN the kernel sends it) the loop sleeps on the bus
instead and starts each cycle when its SYNC arrives, timed from the frame's receive stamp;
a SYNC taken later than the sensor window is an overrun and skipped, and none within
`stall_fault_periods` is a stall: the cycle runs without it and faults OVERRUN. `lockstep` -
SYNC k+1 as soon as cycle k's exchange is complete.
nodes: a node that boots again (boot-up heartbeat: power cycle, reset) restarts its alive
counters (a stock device has forgotten its configuration), and the NMT master identifies,
prepares and starts it again on the host's RESET (CiA 302's boot-up of a slave), so RESET +
ENABLE recovers from a plant that was restarted.
shutdown: valves HOLD for `shutdown_hold_cycles`, DISABLED for `shutdown_disable_cycles`.
"""

from __future__ import annotations

import math
import queue
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from firmware_py.controller import Controller
from firmware_py.runtime.configure import ConfigurationError
from firmware_py.runtime.hardware import Hardware
from firmware_py.runtime.hardware_canopen import CanopenHardware
from firmware_py.runtime.hardware_dbc import DbcHardware
from firmware_py.runtime.identify import IdentityError, identify, loop_sdo_clients
from firmware_py.runtime.sync import BusSync, bus_sends_sync
from firmware_py.supervision.supervisor import LATCHED, emergency_code
from physics.constants import BAR
from program.realtime import percentiles_us
from protocol.canopen_layout import LAYOUT_FILE
from protocol.codec import CODECS, STANDARD_ID_MASK, FrameDecoder
from protocol.dbc import sync_counter_overflow, truth_phase
from protocol.devices import DEVICE_PROFILES, SDO_RESPONSE_BASE
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.enums import PACINGS, Fault, NmtCommand, NmtState, Pacing
from protocol.interfaces import (
    clock_values,
    load_values,
    payload_values,
)
from protocol.nodes import CONTROLLER_NODE
from protocol.outbox import Outbox

HISTORY = 1 << 16                       # cycles kept for the timing percentiles
# the cycle's phases, in order (seconds each, per cycle, in `phase_s`): SYNC sent; the sensor
# window less the frames' handling; the frames' handling (decode, dispatch); read; update;
# write (frames encoded and sent, heartbeat); host work after the write (a waypoint commit);
# idle until the next cycle (sleep, spin, frames handled meanwhile)
PHASES = ("sync", "window", "decode", "read", "update", "write", "host_work", "idle")
(PH_SYNC, PH_WINDOW, PH_DECODE, PH_READ, PH_UPDATE, PH_WRITE, PH_HOST_WORK, PH_IDLE) = range(len(PHASES))
HOST_FRAMES = ("HOST_CMD", "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT", "HOST_WAYPOINT_TIME", "HOST_TEST")


class ActivationError(RuntimeError):
    """The nodes did not come up (no heartbeat) within the activation timeout."""


class _CountedSend:
    """The loop's bus for canopen's SDO client: what it sends is counted as the loop's own
    (`sent`, added to the loop's tally by the loop's own thread)."""

    def __init__(self, loop):
        self.loop = loop
        self.sent = 0

    def send(self, msg, timeout=None) -> None:
        self.loop.bus.send(msg)
        self.sent += 1


class _Reidentification:
    """Rebooted nodes identified and prepared again beside the running cycle (a thread: the
    SDO exchanges take tens of ms, which the cycle's SYNC and the valves' watchdogs cannot
    wait); the loop hands it the SDO answers it receives and reads the verdict when `done`."""

    def __init__(self, loop, nodes: list[int]):
        self.answers: queue.SimpleQueue = queue.SimpleQueue()
        self.send = _CountedSend(loop)
        self.refusal: Exception | None = None
        self.prepared = None
        hardware = loop.hardware
        client_of = loop_sdo_clients(self.send, self._receive, lambda msg: None, loop.clock,
                                     loop.cfg.devices.sdo_timeout_s)
        self._thread = threading.Thread(target=self._run, args=(hardware, client_of, nodes),
                                        name="reidentify", daemon=True)
        self._thread.start()

    def _run(self, hardware, client_of, nodes: list[int]) -> None:
        expected = hardware.expected_devices()
        try:
            identify(client_of, {n: expected[n] for n in nodes}, hardware.names)
            self.prepared = hardware.prepare(client_of, nodes)
        except (IdentityError, ConfigurationError) as refusal:
            self.refusal = refusal

    def _receive(self, timeout_s: float):
        try:
            return self.answers.get(timeout=timeout_s)
        except queue.Empty:
            return None

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()


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
    syncs_skipped: int = 0        # the bus's SYNC: ones the loop did not run a cycle on (late, lost)
    syncs_missing: int = 0        # ... stretches of stall_fault_periods without one


class ControllerLoop:
    def __init__(self, bus, controller: Controller, rate_hz: float, pacing: str, clock=time.perf_counter,
                 log=None, devices: str = "hydrapod", layout=LAYOUT_FILE):
        if pacing not in PACINGS:
            raise ValueError(f"pacing must be one of {PACINGS}, got {pacing!r}")
        self.bus, self.controller, self.pacing, self.clock = bus, controller, pacing, clock
        self._pacing_value = int(Pacing[pacing.upper()])
        self.cfg = controller.cfg
        self.period_s = 1.0 / rate_hz
        self.log = log or (lambda text: print(f"controller: {text}", file=sys.stderr, flush=True))
        n = controller.status.n_legs
        has_imu = controller.status.n_nodes > n
        self.stats = Stats()
        if devices not in DEVICE_PROFILES:
            raise ValueError(f"devices must be one of {', '.join(DEVICE_PROFILES)}, got {devices!r}")
        # the rig's devices: the project's own nodes, or stock CANopen devices
        self.hardware: Hardware = DbcHardware(n, has_imu, self.cfg.devices, self.stats, clock) \
            if devices == "hydrapod" else CanopenHardware(n, has_imu, self.stats, clock, layout)
        self.meas, self.cmd = self.hardware.new_measurements(), controller.new_interfaces()[1]
        self.nodes = self.hardware.nodes
        rx = list(HOST_FRAMES)
        if pacing == "lockstep":            # the emulator's last frame of each SYNC closes the window
            rx.append("EMU_TRUTH")
        self.decoder = FrameDecoder(rx)
        self._host_ids = {CODECS[name].frame_id: name for name in HOST_FRAMES}
        self._truth_id = CODECS["EMU_TRUTH"].frame_id if pacing == "lockstep" else -1
        self._truth_values = self.decoder.values["EMU_TRUTH"] if pacing == "lockstep" else None
        self._truth_phase = CODECS["EMU_TRUTH"].index["SYNC_PHASE"]
        self._closed = False                        # lockstep: this SYNC's EMU_TRUTH came
        self.out_sync = Outbox("SYNC")
        self.out_nmt = Outbox("NMT")
        self.out_status = Outbox("CTRL_STATUS")
        self.out_ack = Outbox("CTRL_ACK")
        self.out_heartbeat = Outbox(f"HEARTBEAT_{CONTROLLER_NODE}")
        self.out_emcy = Outbox(f"EMCY_{CONTROLLER_NODE}")
        self._status_schedule = CODECS["CTRL_STATUS"].schedule
        # the hexapod's payload (its estimate, or the declared payload)
        self.out_payload = Outbox("CTRL_PAYLOAD") if has_imu else None
        self._declared_payload_kg = controller.cfg.hexapod.payload_kg
        self._payload_schedule = CODECS["CTRL_PAYLOAD"].schedule
        # ... and its reference's clock (online time scaling)
        self.out_clock = Outbox("CTRL_CLOCK") if has_imu else None
        self._clock_schedule = CODECS["CTRL_CLOCK"].schedule
        # every rig: the legs' estimates of chapter 7.5, one leg per frame
        self.out_load = Outbox("CTRL_LOAD")
        self._load_schedule, self._load_leg = CODECS["CTRL_LOAD"].schedule, 0
        self._overflow = sync_counter_overflow()
        self.sync_counter = 0
        # the bus's periodic SYNC, or None: the loop sends it
        self.bus_sync = BusSync(bus, self.period_s, self._overflow) \
            if bus_sends_sync(self.cfg.timing.sync_source, pacing, bus) else None
        self._bus_sync_id = self.bus_sync.frame_id if self.bus_sync is not None else -1
        self._pending_sync = None                    # the newest bus SYNC not yet taken
        self.compute_s = np.zeros(HISTORY)
        self.period_error_s = np.zeros(HISTORY)
        self.phase_s = np.zeros((HISTORY, len(PHASES)))
        self._decode_s = 0.0                         # frames' handling inside this cycle's window
        self._cycle_end = math.nan
        self._compute_max = 0.0
        self._period_error_max = 0.0
        self._last_sync = math.nan
        self._next_heartbeat = 0.0
        self._overrun = False
        self._next_deadline = math.inf          # realtime: the next SYNC's deadline (lockstep: none)
        self._stalled = False                        # seen since the last read
        self._latched = False                       # the last EMCY_16 said: a fault is latched
        self._stall_s = self.cfg.timing.stall_fault_periods * self.period_s if pacing == "realtime" else math.inf
        self._restarts_seen = 0                     # the controller's restart requests carried out
        self._reidentification: _Reidentification | None = None     # ... being identified again
        self.state_at_stop = None                   # the controller's state when the shutdown began

    def can_filters(self) -> list[dict]:
        """The acceptance filter: the devices' frames, the host's (and EMU_TRUTH), the nodes' SDO
        answers, and the bus's SYNC when the bus sends it."""
        sync = [{"can_id": self._bus_sync_id, "can_mask": STANDARD_ID_MASK, "extended": False}] \
            if self.bus_sync is not None else []
        return self.hardware.filters() + self.decoder.can_filters() + sync + [
            {"can_id": SDO_RESPONSE_BASE + node, "can_mask": STANDARD_ID_MASK, "extended": False}
            for node in self.nodes]

    # -- receive --------------------------------------------------------------------------
    def dispatch(self, msg) -> None:
        """One received frame: decoded, and recorded for the next read or queued for the host link."""
        frame_id = msg.arbitration_id
        if frame_id == self._bus_sync_id:            # the bus's SYNC is the loop's frame
            self.stats.frames_sent += 1
            self._pending_sync = msg                 # the wait for the next SYNC takes it
            return
        job = self._reidentification
        if job is not None and SDO_RESPONSE_BASE < frame_id < SDO_RESPONSE_BASE + 0x80:
            job.answers.put(msg)                     # an answer for the nodes being identified
            return
        if self.hardware.dispatch(msg):
            return
        status = self.decoder.receive_message(msg)
        if status is RxStatus.UNKNOWN_ID:
            self.stats.unknown_frames += 1
            return
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                self.stats.e2e_errors += 1
            return
        if frame_id == self._truth_id:               # the emulator has sent all it had for this SYNC
            self._closed = int(self._truth_values[self._truth_phase]) == truth_phase(self.sync_counter)
            return
        name = self._host_ids.get(frame_id)
        if name is not None:
            self._host_frame(name, self.decoder.values[name])

    def _host_frame(self, name: str, v) -> None:
        host = self.controller.host
        if name == "HOST_CMD":
            self.stats.host_commands += 1
            host.command(int(v[2]), int(v[3]), int(v[4]))                          # COMMAND, ARGUMENT, SEQ
        elif name == "HOST_WAYPOINT_POS":
            host.waypoint_position(int(v[2]), float(v[3]), float(v[4]), float(v[5]))       # TAG, X, Y, Z
        elif name == "HOST_WAYPOINT_ROT":
            host.waypoint_rotation(int(v[2]), float(v[3]), float(v[4]), float(v[5]))       # TAG, ROLL, PITCH, YAW
        elif name == "HOST_WAYPOINT_TIME":                # TAG, SEQ, SEGMENT_TIME, ACCEL_TIME, FLAGS
            host.waypoint_commit(int(v[2]), int(v[3]), float(v[4]), float(v[5]), int(v[6]))
        else:                                             # HOST_TEST: MODE, SEQ, VALVE, FORCE, DURATION
            host.test(int(v[2]), int(v[3]), float(v[4]), float(v[5]), float(v[6]))

    def _collect(self, deadline: float) -> None:
        """Receive until every LEG_STATE of the cycle is in or the window closes; frames
        already waiting in the receive queue when it closes arrived in time and are taken.
        Lockstep: the emulator's EMU_TRUTH for this SYNC closes it too (a lost frame costs no
        wait, and a machine stall shorter than the timeout loses nothing)."""
        self._closed = False
        while not self.hardware.all_fresh() and not self._closed:
            remaining = deadline - self.clock()
            msg = self.bus.recv(timeout=max(remaining, 0.0))
            self._note_stall()
            if msg is None:
                if remaining <= 0.0:
                    return
                continue
            received = self.clock()
            self.dispatch(msg)
            self._decode_s += self.clock() - received

    def _drain_until(self, deadline: float) -> None:
        """Between cycles: handle host and node frames until `deadline - spin`, then spin."""
        spin = self.cfg.timing.spin_s
        while True:
            remaining = deadline - spin - self.clock()
            if remaining <= 0.0:
                break
            msg = self.bus.recv(timeout=remaining)
            self._note_stall()
            if msg is not None:
                self.dispatch(msg)
        while self.clock() < deadline:
            pass

    def _note_stall(self) -> None:
        """Realtime: the process was not running for longer than the valves' watchdog."""
        if self.clock() - self._last_sync > self._stall_s:
            self._stalled = True

    # -- read / write ---------------------------------------------------------------------
    def read(self, now: float) -> None:
        """The cycle's Measurements (the one place they are filled): the devices' samples and
        events (`Hardware.read`), and the loop's own since the last read."""
        meas = self.meas
        self.hardware.read(meas, now)
        meas.nodes_starting = self._reidentification is not None
        meas.stalled, self._stalled = self._stalled, False
        meas.overrun = self._overrun

    def _send(self, outbox: Outbox) -> None:
        if outbox.encode():
            try:
                self.bus.send(outbox.message)
            except Exception as exc:               # a full queue or a bus error drops the frame
                self.log(f"send {outbox.codec.name} failed: {exc}")
                return
            self.stats.frames_sent += 1

    def write(self) -> None:
        """The valves' commands (the hardware's), CTRL_STATUS when due, CTRL_ACK, NMT start."""
        status, cmd = self.controller.status, self.cmd
        self.hardware.write(cmd, self._send)
        if self._status_schedule.due(self.sync_counter):
            v = self.out_status.values
            i = self.out_status.index
            v[i["STATE"]] = int(status.state)
            v[i["PACING"]] = self._pacing_value
            v[i["FAULT_CODE"]] = int(status.fault)
            v[i["CONTROLLER"]] = status.kind
            v[i["COMPUTE_TIME_MAX"]] = self._compute_max
            v[i["PERIOD_ERROR_MAX"]] = self._period_error_max
            v[i["OVERRUNS"]] = self.stats.overruns % 256
            v[i["ACTIVE_WAYPOINT"]] = status.active_waypoint % 256
            self._send(self.out_status)
            self._compute_max = 0.0
            self._period_error_max = 0.0
        if self.out_payload is not None and self._payload_schedule.due(self.sync_counter):
            payload_values(self.out_payload.values, self.out_payload.index, status.payload_mass_kg,
                           status.payload_com_m, self._declared_payload_kg)
            self._send(self.out_payload)
        if self._load_schedule.due(self.sync_counter):
            leg = self._load_leg
            load_values(self.out_load.values, self.out_load.index, leg, status.load_mass_kg[leg],
                        status.load_pressure_pa[leg], status.friction_n[leg])
            self._send(self.out_load)
            self._load_leg = (leg + 1) % status.n_legs
        if self.out_clock is not None and self._clock_schedule.due(self.sync_counter):
            clock_values(self.out_clock.values, self.out_clock.index, status.motion_time_periods > 0.0,
                         status.time_scaled, status.time_rate, status.motion_time_periods)
            self._send(self.out_clock)
        self._send_acks()
        if status.restart_requests != self._restarts_seen and self._reidentification is None:
            self._restarts_seen = status.restart_requests
            if not self.hardware.all_in_state(lambda state: state == NmtState.OPERATIONAL):
                self._restart_booted()               # nodes that rebooted since activation
        job = self._reidentification
        if job is not None and job.done:
            self._reidentification = None
            self.stats.frames_sent += job.send.sent
            if job.refusal is None:
                self.hardware.adopt(job.prepared)
                self.hardware.booted.clear()
                self._nmt_start()
            else:
                self.log(f"restart refused: {job.refusal}")

    def _send_acks(self) -> None:
        acks = self.controller.host.acks
        while acks:
            kind, seq, result, time_scale = acks.popleft()
            v, i = self.out_ack.values, self.out_ack.index
            v[i["KIND"]], v[i["SEQ"]], v[i["RESULT"]] = kind, seq % 256, result
            v[i["TIME_SCALE"]] = time_scale
            v[i["QUEUE_FREE"]] = self.controller.status.queue_free
            self._send(self.out_ack)

    def _nmt_start(self) -> None:
        self.out_nmt.values[:] = (NmtCommand.START, 0)
        self._send(self.out_nmt)

    def _heartbeat(self, now: float) -> None:
        if now >= self._next_heartbeat:
            self.out_heartbeat.values[0] = NmtState.OPERATIONAL
            self._send(self.out_heartbeat)
            self._next_heartbeat = now + self.cfg.timing.heartbeat_s

    # -- one cycle ------------------------------------------------------------------------
    def cycle(self, sync_at: float | None = None) -> None:
        """SYNC, collect, read, update, write, then host work (pacing is `_run_cycles`'s).
        `sync_at`: the bus sent this cycle's SYNC then (its counter is `sync_counter`)."""
        now = self.clock() if sync_at is None else sync_at
        self._note_stall()
        k = self.stats.cycles % HISTORY
        phase = self.phase_s[k]
        phase[PH_IDLE] = now - self._cycle_end if not math.isnan(self._cycle_end) else 0.0
        if not math.isnan(self._last_sync):
            error = abs(now - self._last_sync - self.period_s)
            self.period_error_s[k] = error
            self._period_error_max = max(self._period_error_max, error)
        self._last_sync = now
        if sync_at is None:
            self.sync_counter = self.sync_counter % self._overflow + 1
            self.out_sync.values[0] = self.sync_counter
            self._send(self.out_sync)
        sent = self.clock()
        self.decoder.begin_cycle()
        self.hardware.begin_cycle(self.sync_counter)
        window = self.cfg.timing.sync_window_fraction * self.period_s if self.pacing == "realtime" \
            else self.cfg.timing.lockstep_timeout_s
        self._decode_s = 0.0
        self._collect(now + window)
        self.stats.missing_frames += self.hardware.end_cycle()
        start = self.clock()
        status = self.controller.status
        faults_before = status.faults
        self.read(start)
        read = self.clock()
        self.controller.update(self.meas, self.cmd)
        updated = self.clock()
        self.write()
        self._heartbeat(start)
        self.stats.faults += status.faults - faults_before
        written = self.clock()
        compute = written - start
        self.compute_s[k] = compute
        phase[PH_SYNC], phase[PH_WINDOW], phase[PH_DECODE] = sent - now, start - sent - self._decode_s, self._decode_s
        phase[PH_READ], phase[PH_UPDATE], phase[PH_WRITE] = read - start, updated - read, written - updated
        self._compute_max = max(self._compute_max, compute)
        self.stats.cycles += 1
        if status.faults != faults_before:
            self._log_fault(now)
        self._report_latch()
        # after the write: its cost never delays VALVE_CMD, and it waits when the SYNC is near
        self.controller.after_write(self._next_deadline - self.clock(), self.clock)
        self._cycle_end = self.clock()
        phase[PH_HOST_WORK] = self._cycle_end - written

    def _report_latch(self) -> None:
        """EMCY_16 when the controller latches a fault or an e-stop (its code in DETAIL, the
        leg in INFO), and with ERROR_CODE 0 when a RESET clears it: what a CANopen watcher
        listens for."""
        status = self.controller.status
        latched = status.state in LATCHED
        if latched == self._latched:
            return
        self._latched = latched
        v, i = self.out_emcy.values, self.out_emcy.index
        v[i["ERROR_CODE"]] = emergency_code(status.fault) if latched else 0
        v[i["ERROR_REGISTER"]] = 1 if latched else 0          # CiA 301 bit 0: generic error
        v[i["STATE"]] = int(status.state)
        v[i["DETAIL"]] = int(status.fault) if latched else 0
        v[i["SYNC_COUNTER"]] = self.sync_counter
        v[i["INFO"]] = status.fault_leg if latched else 0         # the leg a leg fault was isolated to
        self._send(self.out_emcy)

    def _log_fault(self, sync_time: float) -> None:
        """One stderr line when the controller faults (an event, not the steady cycle): which
        legs' frames were missing or rejected how many cycles in a row, and what the receiver
        last made of each; the leg a SENSOR_TIMEOUT or E2E_ERROR came from is named here."""
        s = self.controller.status
        leg = f" leg {s.fault_leg}" if s.fault_leg else ""
        self.log(f"fault {s.fault.name}{leg} at cycle {self.stats.cycles}: residual/threshold "
                 f"{[round(r, 2) for r in s.residual_ratio.tolist()]}, missing in a row "
                 f"{s.missing_in_row.tolist()}, rejected in a row {s.rejected_in_row.tolist()}, "
                 f"{self.hardware.leg_report()}, overruns in a row {s.overruns_in_row}, this cycle "
                 f"{1e6 * (self.clock() - sync_time):.0f} us after its SYNC{self._supply_note(s)}")

    @staticmethod
    def _supply_note(s) -> str:
        """What a SUPPLY_PRESSURE is measured against, in the operator's units."""
        if s.fault is not Fault.SUPPLY_PRESSURE:
            return ""
        if math.isnan(s.supply_measured_pa):
            return "; the P-port transducers' samples off the model's flow band while moving"
        return (f"; supply measured {s.supply_measured_pa / BAR:.1f} bar at rest (the P-port transducers' mean), "
                f"configured {s.supply_configured_pa / BAR:.1f} bar ([hydraulic_model] supply_pressure_bar)")

    # -- lifecycle ------------------------------------------------------------------------
    def activate(self, should_stop=lambda: False) -> None:
        """Every node heard, identified and prepared (a stock device: configured by SDO), then
        NMT start until every node reports OPERATIONAL, then HOLD cycles, then IDLE/READY. A
        node that is not its configured device: IdentityError naming it; one that refuses its
        configuration: ConfigurationError; no node is started then."""
        cfg = self.cfg
        give_up = self.clock() + cfg.timing.activation_timeout_s
        self._wait(lambda state: state != -1, "heartbeat", give_up, should_stop)
        hardware = self.hardware
        sdo = _CountedSend(self)
        client_of = loop_sdo_clients(sdo, self.bus.recv, self.dispatch, self.clock, cfg.devices.sdo_timeout_s)
        try:                                         # before the first SYNC: the loop may wait
            found = identify(client_of, hardware.expected_devices(), hardware.names)
            hardware.adopt(hardware.prepare(client_of, hardware.nodes))
        finally:
            self.stats.frames_sent += sdo.sent
        hardware.booted.clear()
        revisions = sorted({f"{identity.revision:#x}" for identity in found.values()})
        self.log(f"identified node(s) {sorted(found)} as configured ({hardware.describe()}; revision(s) "
                 f"{', '.join(revisions)})")
        self._nmt_start()                 # always: a new master's frames start their E2E counters afresh
        # the start's own time: the SDO configuration before it has its own timeouts
        give_up = self.clock() + cfg.timing.activation_timeout_s
        self._wait(lambda state: state == NmtState.OPERATIONAL, "OPERATIONAL heartbeat", give_up, should_stop,
                   self._nmt_start)
        self.controller.reset_valves()               # one Reset pulse: clears faults left from before
        self._run_cycles(cfg.timing.hold_cycles, should_stop)
        self.controller.activated(cfg.supervisor.auto_enable)
        status = self.controller.status
        self.log(f"active: rig={status.rig} state={status.state.name} pacing={self.pacing} "
                 f"rate={1.0 / self.period_s:g} Hz")

    def _restart_booted(self) -> None:
        """NMT start for the nodes that stopped; those that booted since they were identified
        are identified again first, beside the cycle (`_Reidentification`), and started when
        they prove to be their configured device."""
        booted = self.hardware.booted
        if not booted:
            self._nmt_start()
            return
        self._reidentification = _Reidentification(self, sorted(booted))

    def _wait(self, ready, what: str, give_up: float, should_stop, every_200_ms=None) -> None:
        """Receive until `ready(state)` holds for every node's NMT state (heard: not -1);
        `every_200_ms` sent meanwhile; ActivationError naming the nodes at `give_up`."""
        next_send = 0.0
        while not self.hardware.all_in_state(ready):
            now = self.clock()
            if now > give_up or should_stop():
                missing = self.hardware.not_in_state(ready)
                raise ActivationError(f"no {what} from node(s) {missing} within "
                                      f"{self.cfg.timing.activation_timeout_s:g} s")
            if every_200_ms is not None and now >= next_send:
                every_200_ms()
                next_send = now + 0.2
            msg = self.bus.recv(timeout=0.02)
            if msg is not None:
                self.dispatch(msg)

    def _run_cycles(self, count: int | None, should_stop) -> None:
        if self.bus_sync is not None:
            self._run_bus_cycles(count, should_stop)
            return
        deadline = self.clock()
        done = 0
        while (count is None or done < count) and not should_stop():
            if self.pacing == "realtime":
                self._next_deadline = deadline + self.period_s
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

    def _run_bus_cycles(self, count: int | None, should_stop) -> None:
        """Realtime on the bus's SYNC: each cycle when its SYNC arrives."""
        self.bus_sync.start()
        done = 0
        while (count is None or done < count) and not should_stop():
            sync_at = self._await_sync()
            self._next_deadline = sync_at + self.period_s
            self.cycle(sync_at)
            done += 1

    def _await_sync(self) -> float:
        """Handle frames until the bus's next SYNC; when it was sent, on the loop's clock (its
        receive stamp's age subtracted). A SYNC older than the sensor window is an overrun and
        skipped (the next is taken instead, never a burst); none within `stall_fault_periods`
        of the last is a stall, and the cycle runs now without one."""
        window = self.cfg.timing.sync_window_fraction * self.period_s
        give_up = (self.clock() if math.isnan(self._last_sync) else self._last_sync) + \
            self.cfg.timing.stall_fault_periods * self.period_s
        self._overrun = False
        while True:
            msg, self._pending_sync = self._pending_sync, None
            if msg is None:                              # wait: `dispatch` keeps the SYNC when it comes
                remaining = give_up - self.clock()
                if remaining <= 0.0:
                    self._stalled = True
                    self.stats.syncs_missing += 1
                    return self.clock()
                received = self.bus.recv(timeout=remaining)
                if received is not None:
                    self.dispatch(received)
                continue
            age = max(time.time() - msg.timestamp, 0.0) if msg.timestamp > 0.0 else 0.0
            if age > window:                             # taken too late to collect its samples
                self._overrun = True
                self.stats.overruns += 1
                continue
            self._note_sync_counter(msg.data[0])
            return self.clock() - age

    def _note_sync_counter(self, counter: int) -> None:
        """The bus's counter becomes the cycle's; the SYNCs between are counted as skipped."""
        if self.sync_counter:
            self.stats.syncs_skipped += (counter - self.sync_counter - 1) % self._overflow
        self.sync_counter = counter

    def run(self, should_stop) -> None:
        self._run_cycles(None, should_stop)

    def shutdown(self) -> None:
        """Valves to HOLD, then DISABLED, over a few cycles; SYNC keeps running meanwhile."""
        never = lambda: False  # noqa: E731
        self.state_at_stop = self.controller.status.state
        self.controller.shut_down()
        self._run_cycles(self.cfg.timing.shutdown_hold_cycles, never)
        self.controller.power_off()
        self._run_cycles(self.cfg.timing.shutdown_disable_cycles, never)
        if self.bus_sync is not None:
            self.bus_sync.stop()

    def timing(self) -> dict:
        """Percentiles (us) of the compute time, the period error and each phase of the cycle,
        over the last HISTORY cycles."""
        n = min(self.stats.cycles, HISTORY)
        if not n:
            return {}
        out = {"compute_us": percentiles_us(self.compute_s[:n]),
               "period_error_us": percentiles_us(self.period_error_s[:n])}
        out["phases_us"] = {name: percentiles_us(self.phase_s[:n, j]) for j, name in enumerate(PHASES)}
        return out

    def summary(self) -> dict:
        status, s = self.controller.status, self.stats
        return {"rig": status.rig, "controller": status.kind, "pacing": self.pacing,
                "cycles": s.cycles, "overruns": s.overruns, "e2e_errors": s.e2e_errors,
                "missing_frames": s.missing_frames, "faults": s.faults, "fault_code": status.fault.name,
                **status.margins.as_dict(),
                "state": (self.state_at_stop or status.state).name, "emergencies": s.emergencies,
                "host_commands": s.host_commands, "frames_sent": s.frames_sent,
                "sync_source": "bus" if self.bus_sync is not None else "loop",
                "syncs_skipped": s.syncs_skipped, "syncs_missing": s.syncs_missing, "timing": self.timing()}
