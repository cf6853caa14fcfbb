"""Stock CANopen devices (the canopen profile, `protocol/devices/canopen-layout.toml`): per leg a
CiA 408 valve (RPDO: control word, spool setpoint; TPDO: status word, actual spool), a CiA
406 encoder and a CiA 404 measuring device (load cell, chamber and supply pressures); the
hexapod's IMU as a CiA 404 device.

Before its NMT start each device is identified (0x1000, 0x1018 against its EDS) and
configured by SDO (`runtime/configure.py`: its settings, its PDOs in CiA 301's order, all
read back); its PDOs are then compiled from what it holds (`protocol.pdo`), so which object
travels in which frame is the device's configuration, never this code. A leg's samples of a
cycle are in when every TPDO it sends at every SYNC has come; the objects a TPDO carries go
where the profile says (`protocol.canopen_profile`), in SI. The valves' RPDOs carry each
cycle's ValveCommands. No E2E: a PDO shorter than its mapping is rejected (CiA 301), as a
frame that fails E2E is in the project's own profile.
"""

from __future__ import annotations

import math

import can
import numpy as np

from firmware_py.runtime.configure import ConfigurationError, configure_node, node_writes
from firmware_py.runtime.hardware import Hardware
from protocol import canopen_profile as cp
from protocol.canopen_layout import LAYOUT_FILE, Device, load_layout
from protocol.codec import STANDARD_ID_MASK, EncodeStatus
from protocol.devices import EMCY_BASE, HEARTBEAT_BASE, identity_of, object_dictionary
from protocol.pdo import RPDO, TPDO, PdoCodec, PdoError, pdo_maps

# what a TPDO's object goes into: the leg's (or the IMU's) latest value, or the valve state
POSITION, FORCE, SPOOL, VALVE_STATE, PRESSURE, ATTITUDE, RATE = range(7)
_SINK_OF_QUANTITY = {"position": POSITION, "force": FORCE, "spool": SPOOL, "valve_state": VALVE_STATE,
                     "pressure": PRESSURE}


class _TxPdo:
    """A valve's RPDO as the controller sends it: its raw values and frame (`Outbox`'s interface)."""

    def __init__(self, device: Device, codec: PdoCodec):
        self.device, self.codec, self.leg = device, codec, device.leg - 1
        entries = codec.pdo.entries()
        self.control_at = [k for k, e in enumerate(entries) if e == cp.CONTROL_WORD]
        self.setpoint_at = [k for k, e in enumerate(entries) if e == cp.SPOOL_SETPOINT]
        self.values = [0] * len(entries)            # Python numbers: no NumPy scalar per cycle
        self.message = can.Message(arbitration_id=codec.frame_id, data=codec.new_buffer(), is_extended_id=False)

    def fill(self, cmd) -> None:
        leg = self.leg
        word = cp.control_word(float(cmd.enable[leg]) != 0.0, float(cmd.hold[leg]) != 0.0,
                               float(cmd.active[leg]) != 0.0, float(cmd.reset[leg]) != 0.0)
        setpoint = float(cmd.spool[leg]) * cp.SPOOL_FULL_SCALE
        if math.isfinite(setpoint):                   # not finite: the codec sends nothing
            setpoint = math.floor(setpoint + 0.5)
        for k in self.control_at:
            self.values[k] = word
        for k in self.setpoint_at:
            self.values[k] = setpoint

    def encode(self) -> bool:
        return self.codec.encode_into(self.values, self.message.data) is not EncodeStatus.REJECTED


class _RxPdo:
    """A device's TPDO as the controller takes it: where each mapped object goes."""

    def __init__(self, device: Device, codec: PdoCodec):
        self.device, self.codec = device, codec
        self.leg = device.leg - 1 if device.leg is not None else -1
        self.values = np.zeros(len(codec.pdo.entries()))
        self.sinks: list[tuple[int, int, int, float]] = []      # (value's index, sink, column, SI per count)
        for k, entry in enumerate(codec.pdo.entries()):
            if device.leg is None:
                if entry in cp.IMU_ATTITUDE:
                    self.sinks.append((k, ATTITUDE, cp.IMU_ATTITUDE.index(entry), cp.ANGLE_STEP_RAD))
                elif entry in cp.IMU_RATE:
                    self.sinks.append((k, RATE, cp.IMU_RATE.index(entry), cp.RATE_STEP_RAD_S))
            elif entry in cp.LEG_MEASURED:
                quantity, step = cp.LEG_MEASURED[entry]
                self.sinks.append((k, _SINK_OF_QUANTITY[quantity], cp.LEG_PRESSURE_COLUMN.get(entry, 0), step))
        self.quantities = {sink for _, sink, _, _ in self.sinks}
        self.every_cycle = codec.pdo.sync_period == 1 and self.leg >= 0 and bool(
            self.quantities & {POSITION, FORCE, SPOOL, VALVE_STATE})
        self.due = False                              # sent at this cycle's SYNC
        self.arrived = False                          # ... and came


class CanopenHardware(Hardware):
    profile = "canopen"

    def __init__(self, n_legs: int, has_imu: bool, stats, clock, layout=LAYOUT_FILE):
        self.layout_file = layout
        self.devices = [d for d in load_layout(n_legs, layout) if has_imu or d.leg is not None]
        imu = [d.node for d in self.devices if d.leg is None]
        super().__init__(n_legs, [d.node for d in self.devices], imu[0] if imu else None, stats, clock)
        self.names = {d.node: d.name for d in self.devices}
        self.valve_nodes = {d.node for d in self.devices if d.kind == "valve"}
        self._device = {d.node: d for d in self.devices}
        self._heartbeat_of_id = {HEARTBEAT_BASE + node: k for k, node in enumerate(self.nodes)}
        self._emcy_of_id = {EMCY_BASE + node: node for node in self.nodes}
        self._rx: dict[int, _RxPdo] = {}              # COB-ID -> a started device's TPDO
        self._tx: list[_TxPdo] = []                   # the valves' RPDOs, by leg
        self._every_cycle: list[_RxPdo] = []
        self._cyclic: list[_RxPdo] = []               # every SYNC-cyclic TPDO: the window waits for those due
        self._due_now = 0                             # TPDOs due at this cycle's SYNC ...
        self._arrived_now = 0                         # ... of which came
        self._arrived_every = 0                       # the every-SYNC ones that came
        self._due = np.zeros(n_legs, dtype=np.int64)      # TPDOs each leg sends every cycle
        self._arrived = np.zeros(n_legs, dtype=np.int64)  # ... of which came this cycle
        self._position = np.zeros(n_legs)
        self._force = np.zeros(n_legs)
        self._spool = np.zeros(n_legs)
        self._valve_state = np.zeros(n_legs, dtype=np.int64)
        self.last_missing = np.zeros(n_legs, dtype=np.int64)  # a leg's TPDOs missing when the window closed
        self._pdos: dict[int, tuple[list[_RxPdo], list[_TxPdo]]] = {}   # node -> its PDOs as configured

    # -- configuration ------------------------------------------------------------------------
    def expected_devices(self) -> dict:
        return {d.node: (identity_of(d.eds), d.eds) for d in self.devices}

    def prepare(self, client_of, nodes) -> dict:
        """Each of `nodes` configured and read back, its PDOs compiled from what it holds;
        ConfigurationError naming a node whose configuration leaves a leg without a sample."""
        prepared = {node: self.compiled(node, configure_node(client_of(node), self._device[node])) for node in nodes}
        self._check_coverage({**self._pdos, **prepared})
        return prepared

    def compiled(self, node: int, written: dict) -> tuple[list[_RxPdo], list[_TxPdo]]:
        """The node's PDOs as it holds them (`written`: (index, sub-index) -> value over its EDS)."""
        device = self._device[node]
        od = object_dictionary(device.eds, node)
        try:
            rx = [_RxPdo(device, PdoCodec(p)) for p in pdo_maps(od, TPDO, device.name, written)]
            tx = [_TxPdo(device, PdoCodec(p)) for p in pdo_maps(od, RPDO, device.name, written)
                  if device.leg is not None and cp.CONTROL_WORD in p.entries()]
        except PdoError as error:
            raise ConfigurationError(f"node {node} ({device.name}): {error}") from None
        return rx, tx

    def as_configured(self) -> dict:
        """Every device's PDOs as `configure_node` leaves them (what a log of a run is read with)."""
        return {d.node: self.compiled(d.node, {(w.index, w.subindex): w.value for w in node_writes(d)})
                for d in self.devices}

    def _check_coverage(self, pdos: dict) -> None:
        """Every leg's position, force, valve state and spool every SYNC, its pressures, a valve
        command, and the hexapod's attitude: else one line naming what is missing."""
        for leg in range(1, self.n_legs + 1):
            rx = [p for node, (r, _) in pdos.items() if self._device[node].leg == leg for p in r]
            every = {s for p in rx if p.codec.pdo.sync_period == 1 for s in p.quantities}
            missing = [q for q in cp.LEG_EVERY_CYCLE if _SINK_OF_QUANTITY[q] not in every]
            if missing:
                raise ConfigurationError(f"leg {leg}: no TPDO sent at every SYNC carries its {', '.join(missing)}: "
                                         "not started")
            if not any(PRESSURE in p.quantities for p in rx):
                raise ConfigurationError(f"leg {leg}: no TPDO carries its chamber pressures: not started")
            if not any(tx for node, (_, tx) in pdos.items() if self._device[node].leg == leg):
                raise ConfigurationError(f"leg {leg}: no RPDO of its valve maps the control word 0x6040: "
                                         "not started")
        if self.has_imu:
            rx = pdos.get(self.imu_node, ([], []))[0]
            if not any(ATTITUDE in p.quantities for p in rx):
                raise ConfigurationError(f"{self.name_of(self.imu_node)}: no TPDO carries the attitude: not started")

    def adopt(self, prepared) -> None:
        self._pdos.update(prepared)
        self._rx = {p.codec.frame_id: p for rx, _ in self._pdos.values() for p in rx}
        self._tx = sorted((p for _, tx in self._pdos.values() for p in tx), key=lambda p: p.leg)
        self._every_cycle = [p for p in self._rx.values() if p.every_cycle]
        self._cyclic = [p for p in self._rx.values() if p.codec.pdo.sync_period >= 1]
        self._due.fill(0)
        for p in self._every_cycle:
            self._due[p.leg] += 1

    def filters(self) -> list[dict]:
        """Every TPDO a layout device may send (its EDS's, and any the configuration moved to),
        heartbeats and EMCY: standard ids 0x080-0x7FF of the layout's nodes."""
        ids = {HEARTBEAT_BASE + n for n in self.nodes} | {EMCY_BASE + n for n in self.nodes}
        for device in self.devices:
            ids.update(p.cob_id for p in pdo_maps(object_dictionary(device.eds, device.node), TPDO, device.name))
        return [{"can_id": i, "can_mask": STANDARD_ID_MASK, "extended": False} for i in sorted(ids)]

    # -- receive ------------------------------------------------------------------------------
    def dispatch(self, msg) -> bool:
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd:
            return False
        frame_id = msg.arbitration_id
        pdo = self._rx.get(frame_id)
        if pdo is not None:
            self._take(pdo, msg.data)
            return True
        k = self._heartbeat_of_id.get(frame_id)
        if k is not None:
            if len(msg.data) >= 1:
                self.heartbeat(k, msg.data[0] & 0x7F)         # bit 7: the toggle of node guarding
            return True
        node = self._emcy_of_id.get(frame_id)
        if node is not None:
            if len(msg.data) >= 2:
                self.emergency(node, msg.data[0] | msg.data[1] << 8)
            return True
        return False

    def _take(self, pdo: _RxPdo, data) -> None:
        leg = pdo.leg
        if not pdo.codec.decode_into(data, pdo.values):       # shorter than its mapping: not processed
            self.stats.e2e_errors += 1
            if leg >= 0:
                self._rejected[leg] = True
            return
        values = pdo.values
        for k, sink, column, step in pdo.sinks:
            x = values[k] * step
            if sink == POSITION:
                self._position[leg] = x
            elif sink == FORCE:
                self._force[leg] = x
            elif sink == SPOOL:
                self._spool[leg] = x
            elif sink == VALVE_STATE:
                self._valve_state[leg] = cp.valve_state(int(values[k]))
            elif sink == PRESSURE:
                self._pressure[leg, column] = x
            elif sink == ATTITUDE:
                self._attitude[column] = x
            else:
                self._rate[column] = x
        if PRESSURE in pdo.quantities:
            self._pressure_valid[leg] = self._pressure_new[leg] = True
        if ATTITUDE in pdo.quantities:
            self._attitude_new = True
        if RATE in pdo.quantities:
            self._rate_new = True
        if pdo.due and not pdo.arrived:
            pdo.arrived = True
            self._arrived_now += 1
            if pdo.every_cycle:
                self._arrived[leg] += 1
                self._arrived_every += 1

    def restarted(self, node: int) -> None:
        """A rebooted device forgot its configuration: its frames are not taken until it is
        configured again."""
        rx, _ = self._pdos.get(node, ([], []))
        for p in rx:
            if self._rx.get(p.codec.frame_id) is p:
                del self._rx[p.codec.frame_id]

    # -- the cycle ----------------------------------------------------------------------------
    def begin_window(self, counter: int) -> None:
        due = 0
        for p in self._cyclic:
            p.arrived = False
            p.due = p.codec.pdo.due_at(counter)
            due += p.due
        self._due_now, self._arrived_now, self._arrived_every = due, 0, 0
        self._arrived.fill(0)

    def end_cycle(self) -> int:
        np.subtract(self._due, self._arrived, out=self.last_missing)
        return len(self._every_cycle) - self._arrived_every

    def all_fresh(self) -> bool:
        """Every TPDO due at this SYNC came (the pressures' and the IMU's on their SYNCs too,
        so what a cycle reads does not depend on when the window closed)."""
        return self._arrived_now >= self._due_now

    def read_legs(self, meas) -> None:
        np.greater_equal(self._arrived, self._due, out=meas.fresh)
        np.copyto(meas.position_m, self._position, where=meas.fresh)
        np.copyto(meas.force_n, self._force, where=meas.fresh)
        np.copyto(meas.spool, self._spool, where=meas.fresh)
        np.copyto(meas.valve_state, self._valve_state, where=meas.fresh)
        meas.sensor_fault.fill(False)                # a sensor's fault comes as its EMCY

    def write(self, cmd, send) -> None:
        for pdo in self._tx:
            pdo.fill(cmd)
            send(pdo)

    def leg_report(self) -> str:
        return f"TPDOs missing at the window's close per leg {self.last_missing.tolist()}"

    def describe(self) -> str:
        return f"{self.layout_file.name}: {len(self.devices)} stock devices, each configured by SDO"
