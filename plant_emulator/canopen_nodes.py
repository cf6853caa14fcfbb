"""The emulated rig as stock CANopen devices (`--devices canopen`): per leg a CiA 408 valve, a
CiA 406 encoder and a CiA 404 measuring device, and the hexapod's IMU as a CiA 404 device, at
the node ids of `protocol/devices/canopen-layout.toml`.

Each device answers SDO from its EDS (canopen's `LocalNode`, which refuses a mapping the
device cannot carry) and carries its PDOs as the master configured them: at its NMT start
each device's PDOs are compiled (`protocol.pdo`) from its EDS and what was written to it,
so a wrong mapping shows on the bus; its heartbeat producer time (0x1017) and, a valve, its
RPDO timeout (0x1400:5) are what was written too. A reset node forgets what was written, as a
rebooted device does. The valves take their RPDO (control word, spool setpoint) into the same CiA
408 state machine as the DBC profile's (`valve_node.py`), applied at the next SYNC; the
sensors send their TPDOs at the SYNCs their transmission types and SYNC start values say,
with the rig's samples in the profile's steps (`protocol.canopen_profile`).
"""

from __future__ import annotations

import sys

import can
import numpy as np

from plant_emulator.devices import EmulatedDevices
from protocol import canopen_profile as cp
from protocol.canopen_layout import LAYOUT_FILE, Device, load_layout
from protocol.codec import EncodeStatus
from protocol.devices import HEARTBEAT_BASE, written_values
from protocol.nodes import IMU_NODE
from protocol.pdo import RPDO, TPDO, PdoCodec, PdoError, object_value, pdo_maps

HEARTBEAT_TIME = (0x1017, 0)                              # producer heartbeat time, ms
RPDO1_TIMEOUT = (0x1400, 5)                               # RPDO1's event timer: its deadline, ms
LEG_PRESSURES = (cp.LEG_PA, cp.LEG_PB, cp.LEG_PS)        # in SimulatedRig.pressure's column order


class _Pdo:
    """A compiled PDO with its buffers: the raw values in mapping order, the frame."""

    def __init__(self, device: Device, codec: PdoCodec):
        self.device, self.codec = device, codec
        self.entries = codec.pdo.entries()
        self.values = np.zeros(len(self.entries))
        # the samples it carries that the DBC profile's schedule may not have taken at a SYNC
        self.pressures = device.leg is not None and any(e in LEG_PRESSURES for e in self.entries)
        self.attitude = device.leg is None and any(e in cp.IMU_ATTITUDE for e in self.entries)
        self.rate = device.leg is None and any(e in cp.IMU_RATE for e in self.entries)
        self.message = can.Message(arbitration_id=codec.frame_id, data=codec.new_buffer(), is_extended_id=False)
        self.fault_node = device.leg if device.leg is not None else IMU_NODE     # EMU_CTRL's target for its frames


class CanopenNodes:
    """The stock devices of a rig with `n_legs` legs, as `layout` places them; `send(message)`
    puts a frame on the bus."""

    def __init__(self, n_legs: int, send, layout=LAYOUT_FILE):
        self.layout = load_layout(n_legs, layout)
        self.device = {d.node: d for d in self.layout}
        self.valve_node = {d.leg: d.node for d in self.layout if d.kind == "valve"}
        # each leg's nodes (its valve, encoder and measuring device): any started samples the leg
        self.leg_nodes = {leg: tuple(d.node for d in self.layout if d.leg == leg) for leg in self.valve_node}
        self.sdo = EmulatedDevices({d.node: d.eds for d in self.layout}, send)
        self.send = send
        self.tpdos: dict[int, list[_Pdo]] = {}          # node -> its TPDOs as started
        # node -> what was written to it when it started (compiling its PDOs takes ~2 ms here,
        # ~20x that in an emulated VM: a master repeating its START must not cost it again)
        self._started_with: dict[int, dict] = {}
        self._tx_order: list[int] = []                  # started nodes, the IMU's first, then by leg
        self.rpdo_of: dict[int, _Pdo] = {}              # COB-ID -> the RPDO it carries
        self.control = {leg: 0 for leg in self.valve_node}   # each valve's last control word

    @property
    def nodes(self) -> list[int]:
        return sorted(self.device)

    def rpdo_ids(self) -> list[int]:
        """Every RPDO COB-ID any device may be given (its EDS's): the acceptance filters."""
        ids = set()
        for device in self.layout:
            ids.update(pdo.cob_id for pdo in pdo_maps(self.sdo.nodes[device.node].object_dictionary, RPDO,
                                                      device.name))
        return sorted(ids)

    def start(self, node: int) -> bool:
        """NMT start: the node's PDOs as configured now; False (it stays PRE-OPERATIONAL, and
        says why on stderr) when they cannot be carried."""
        device, local = self.device[node], self.sdo.nodes[node]
        od, written = local.object_dictionary, written_values(local)
        if node in self.tpdos and self._started_with.get(node) == written:
            return True              # started as configured already: a repeated START changes nothing
        try:
            tpdos = [_Pdo(device, PdoCodec(pdo)) for pdo in pdo_maps(od, TPDO, device.name, written)]
            rpdos = [_Pdo(device, PdoCodec(pdo)) for pdo in pdo_maps(od, RPDO, device.name, written)]
        except PdoError as error:
            print(f"emulator: node {node} not started: {error}", file=sys.stderr, flush=True)
            return False
        self._forget(node)
        self.tpdos[node] = tpdos
        self._started_with[node] = written
        self._tx_order = sorted(self.tpdos, key=lambda n: (self.device[n].leg or 0, n))
        self.rpdo_of.update({pdo.codec.frame_id: pdo for pdo in rpdos})
        return True

    def _forget(self, node: int) -> None:
        """The node's PDOs as started no longer carried."""
        self.tpdos.pop(node, None)
        self._started_with.pop(node, None)
        self._tx_order = [n for n in self._tx_order if n != node]
        for cob_id in [c for c, pdo in self.rpdo_of.items() if pdo.device.node == node]:
            del self.rpdo_of[cob_id]

    def setting(self, node: int, index: int, sub: int = 0) -> int:
        """An object's value in the node: as written, else its EDS default (0: none)."""
        local = self.sdo.nodes[node]
        return object_value(local.object_dictionary, written_values(local), index, sub) or 0

    def heartbeat_s(self, node: int) -> float:
        """The node's heartbeat producer time (0x1017; 0: it sends none)."""
        return self.setting(node, *HEARTBEAT_TIME) / 1e3

    def rpdo_timeout_ms(self, node: int) -> int:
        """The node's RPDO1 timeout (its event timer, 0x1400:5; 0: not monitored)."""
        return self.setting(node, *RPDO1_TIMEOUT)

    def reset(self, node: int) -> None:
        """NMT reset: the node powers up again with its EDS's defaults."""
        self.sdo.reset(node)
        self._forget(node)

    # -- receive ------------------------------------------------------------------------------
    def receive_rpdo(self, frame_id: int, data, valves, operational) -> int | None:
        """An RPDO for an OPERATIONAL device: a valve's command latched into its driver (applied
        at the next SYNC). Returns the node it was for (None: no RPDO of a started node)."""
        pdo = self.rpdo_of.get(frame_id)
        if pdo is None or not operational(pdo.device.node) or not pdo.codec.decode_into(data, pdo.values):
            return None
        leg = pdo.device.leg
        if leg is None or pdo.device.node != self.valve_node.get(leg):
            return pdo.device.node
        control, setpoint = self.control[leg], 0.0
        for (index, sub), raw in zip(pdo.entries, pdo.values):
            if (index, sub) == cp.CONTROL_WORD:
                control = int(raw)
            elif (index, sub) == cp.SPOOL_SETPOINT:
                setpoint = raw / cp.SPOOL_FULL_SCALE
        self.control[leg] = control
        valves[leg - 1].receive(*cp.control_bits(control), setpoint)
        return pdo.device.node

    # -- transmit -----------------------------------------------------------------------------
    def send_tpdos(self, counter: int, sim, operational, emit) -> None:
        """This SYNC's TPDOs of every OPERATIONAL device, the IMU's first (as the DBC
        profile's), with the samples of `sim` (`simulated_rig.SimulatedRig`); each through
        `emit(node, name, message)` (the injected frame faults of its leg's node id, the IMU's)."""
        for node in self._tx_order:
            if not operational(node):
                continue
            for pdo in self.tpdos[node]:
                if not pdo.codec.pdo.due_at(counter):
                    continue
                if not self._fill(pdo, sim):
                    continue
                if pdo.codec.encode_into(pdo.values, pdo.message.data) is not EncodeStatus.REJECTED:
                    emit(pdo.fault_node, pdo.codec.name, pdo.message)

    def _fill(self, pdo: _Pdo, sim) -> bool:
        """The PDO's values from the rig's samples; False when its leg was not sampled."""
        leg = pdo.device.leg
        i = leg - 1 if leg is not None else -1
        if leg is not None and not sim.sampled[i]:
            return False
        # what the DBC profile's schedule did not sample at this SYNC, sampled now
        if pdo.pressures and not sim.pressure_due[i]:
            sim.sensors.pressures(sim.rig, i, sim.pressure[i])
        if pdo.attitude and not sim.attitude_due:
            sim.sensors.attitude(sim.rig, sim.attitude_rad)
        if pdo.rate and not sim.rate_due:
            sim.sensors.rate(sim.rig, sim.rate_rad_s)
        for k, entry in enumerate(pdo.entries):
            pdo.values[k] = self._value(entry, pdo.device, i, sim)
        return True

    def _value(self, entry, device: Device, i: int, sim) -> float:
        if device.leg is None:                                      # the IMU
            if entry in cp.IMU_ATTITUDE:
                return cp.counts(sim.attitude_rad[cp.IMU_ATTITUDE.index(entry)], cp.ANGLE_STEP_RAD)
            if entry in cp.IMU_RATE:
                return cp.counts(sim.rate_rad_s[cp.IMU_RATE.index(entry)], cp.RATE_STEP_RAD_S)
            return 0.0
        if entry == cp.STATUS_WORD:
            return cp.status_word(sim.valves[i].state)
        if entry == cp.SPOOL_ACTUAL:
            return round(sim.spool_actual(i) * cp.SPOOL_FULL_SCALE)
        if entry == cp.SPOOL_SETPOINT:
            return round(sim.valves[i].setpoint * cp.SPOOL_FULL_SCALE)
        if entry == cp.CONTROL_WORD:
            return self.control[device.leg]
        if entry == cp.POSITION:
            return max(cp.counts(sim.position_m[i], cp.POSITION_STEP_M), 0)
        if entry == cp.LEG_FORCE:
            return cp.counts(sim.force_n[i], cp.FORCE_STEP_N)
        if entry in LEG_PRESSURES:
            return cp.counts(sim.pressure[i][LEG_PRESSURES.index(entry)], cp.PRESSURE_STEP_PA)
        return 0.0

    def heartbeat(self, node: int, state: int) -> can.Message:
        return can.Message(arbitration_id=HEARTBEAT_BASE + node, data=bytes([int(state)]), is_extended_id=False)

