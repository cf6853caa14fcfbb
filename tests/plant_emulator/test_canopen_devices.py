"""The emulator's stock CANopen devices (`Emulator(devices="canopen")`) against an independent
master: the `canopen` library and its documented API only, given the devices' EDS files and
node ids as a lab would get them (the shipped files and the layout's TOML); no project code
on the master's side. It reads every device's identity, device type and PDO mapping by SDO,
drives one valve DISABLED -> HOLD -> ACTIVE with a setpoint, sees its RPDO timeout's fault
reaction and EMCY and resets it, remaps a TPDO and sees the new
mapping on the bus, and finds a reset node back at its EDS's mapping."""

import tomllib
from pathlib import Path

import can
import canopen
import pytest

from tests.support.canopen_rig import CanopenRig

DEVICES = Path(__file__).resolve().parents[2] / "protocol" / "devices"
LAYOUT = tomllib.loads((DEVICES / "canopen-layout.toml").read_text())
KINDS = ("valve", "encoder", "leg_sensors")
DISABLED, HOLD, ACTIVE = 0x8, 0x8 | 0x3, 0x8 | 0x7         # CiA 408 status words: ready, D H M
FAULT_HOLD = 0x3                                           # D H, not ready
RPDO_TIMEOUT = 0x8250                                      # CiA 301's EMCY error code


def _devices(n_legs: int) -> dict[int, str]:
    """node id -> EDS file, from the layout as a lab reads it."""
    out = {}
    for kind in KINDS:
        for leg in range(n_legs):
            out[LAYOUT[kind]["node"] + leg] = LAYOUT[kind]["eds"]
    if n_legs == 6:
        out[LAYOUT["imu"]["node"]] = LAYOUT["imu"]["eds"]
    return out


@pytest.fixture
def bus_with(request):
    """The emulator of `rig` on a virtual channel (tests/support/canopen_rig.py); the master's network."""
    started = []

    def start(rig: str) -> canopen.Network:
        channel = f"canopen-devices-{rig}-{request.node.name}"
        emulated = CanopenRig(rig, channel)
        network = canopen.Network()
        network.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        network.notifier = can.Notifier(network.bus, network.listeners, timeout=0.02)
        started.append((emulated, network))
        return network

    yield start
    for emulated, network in started:
        network.disconnect()
        emulated.close()


def _mapped(pdo_map) -> list[tuple[int, int]]:
    return [(variable.index, variable.subindex) for variable in pdo_map.map]


def test_a_master_reads_every_stock_devices_identity_type_and_mapping_by_sdo(bus_with):
    network = bus_with("hexapod")
    for node_id, eds in _devices(6).items():
        node = network.add_node(node_id, str(DEVICES / eds))
        od = node.object_dictionary
        device_type = int.from_bytes(node.sdo.upload(0x1000, 0), "little")
        assert device_type == od[0x1000].default, (node_id, eds)
        assert node.sdo[0x1018][1].raw == od.device_information.vendor_number
        assert node.sdo[0x1018][2].raw == od.device_information.product_number
        node.tpdo.read()                                        # every TPDO's parameters by SDO
        node.rpdo.read()
        for pdo_map in list(node.tpdo.map.values()) + list(node.rpdo.map.values()):
            if not pdo_map.enabled:
                continue
            expected = [(int(od[pdo_map.map_array.od.index][k].default) >> 16,
                         int(od[pdo_map.map_array.od.index][k].default) >> 8 & 0xFF)
                        for k in range(1, int(od[pdo_map.map_array.od.index][0].default) + 1)]
            assert _mapped(pdo_map) == expected, (node_id, pdo_map.name)
    assert device_type & 0xFFFF == 404                          # the IMU's, last: CiA 404


def _cycle(network, valve, counter: int, control: int, setpoint: int) -> tuple[int, int]:
    """The control word and setpoint in RPDO1, a SYNC; the valve's status word and spool."""
    command = valve.rpdo[1]
    for variable in command.map:
        variable.raw = control if variable.index == 0x6040 else setpoint
    command.transmit()
    network.sync.transmit(counter)
    status = valve.tpdo[1]
    assert status.wait_for_reception(timeout=2.0) is not None, "no TPDO1 after the SYNC"
    values = {variable.index: variable.raw for variable in status.map}
    return values.get(0x6041), values.get(0x6301)


def test_a_master_drives_a_stock_valve_to_active_and_its_remapping_shows_on_the_bus(bus_with):
    network = bus_with("testbench")
    valve = network.add_node(LAYOUT["valve"]["node"], str(DEVICES / LAYOUT["valve"]["eds"]))
    valve.rpdo.read()
    valve.tpdo.read()
    valve.sdo[0x1400][5].raw = 6                  # RPDO1's timeout (its event timer): three SYNCs of 2 ms
    valve.nmt.state = "OPERATIONAL"
    counter, trace = 0, []
    for control, setpoint, syncs in ((0x0, 0, 3), (0x3, 0, 3), (0x7, 4096, 40)):   # DISABLED, HOLD, ACTIVE 25 %
        for _ in range(syncs):
            counter = counter % 240 + 1
            trace.append((control, *_cycle(network, valve, counter, control, setpoint)))
    states = [status for control, status, _ in trace]
    assert states[:3] == [DISABLED] * 3 and states[3:6] == [HOLD] * 3 and states[-1] == ACTIVE
    assert abs(trace[-1][2] - 4096) < 0.05 * 4096, trace[-5:]             # the spool followed: 25 % of 16384

    # the RPDO stops: after the timeout's SYNCs the valve holds (FAULT_HOLD) and says why by EMCY
    valve.emcy.reset()
    for _ in range(4):
        counter = counter % 240 + 1
        network.sync.transmit(counter)
        assert valve.tpdo[1].wait_for_reception(timeout=2.0) is not None
    assert {v.index: v.raw for v in valve.tpdo[1].map}[0x6041] == FAULT_HOLD
    emergencies = [e for e in valve.emcy.log if e.code == RPDO_TIMEOUT]       # as they arrived
    assert len(emergencies) == 1 and emergencies[0].register & 0x10           # a communication error
    # R's rising edge with D and H: back to HOLD; then ACTIVE again
    counter = counter % 240 + 1
    assert _cycle(network, valve, counter, 0x3 | 0x8, 0)[0] == HOLD
    for _ in range(40):
        counter = counter % 240 + 1
        status, spool = _cycle(network, valve, counter, 0x7, 4096)
    assert status == ACTIVE and abs(spool - 4096) < 0.05 * 4096

    # remapped by SDO in PRE-OPERATIONAL: TPDO1 carries the actual spool alone, every SYNC
    valve.nmt.state = "PRE-OPERATIONAL"
    valve.tpdo[1].clear()
    valve.tpdo[1].add_variable(0x6301, 1)
    valve.tpdo[1].trans_type = 1
    valve.tpdo[1].enabled = True
    valve.tpdo.save()
    valve.nmt.state = "OPERATIONAL"
    counter = counter % 240 + 1
    status, spool = _cycle(network, valve, counter, 0x7, 4096)
    assert status is None and abs(spool - 4096) < 0.05 * 4096
    assert len(valve.tpdo[1].data) == 2                                     # the frame: two bytes

    # a reset node powers up with its EDS's mapping: the master must configure it again
    valve.nmt.state = "RESET"
    valve.nmt.wait_for_bootup(timeout=2.0)
    valve.tpdo.read()
    assert _mapped(valve.tpdo[1]) == [(0x6041, 0), (0x6301, 1)]
