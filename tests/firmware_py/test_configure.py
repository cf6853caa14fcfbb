"""Configuring stock CANopen devices before their start (firmware_py/runtime/configure.py):
against the emulated devices the layout's PDOs and SYNC start values are written in CiA 301's
order, read back, and then on the bus; a node that refuses, is silent or reads back otherwise
is one line naming it and the object."""

import json
import time

import can
import canopen
import pytest

from firmware_py.runtime.configure import COB_ID_INVALID, ConfigurationError, Write, configure, node_writes
from protocol.canopen_layout import Device, load_layout
from protocol.codec import CODECS
from protocol.devices import object_dictionary, written_values
from tests.support.canopen_rig import CanopenRig
from tests.support.cli import hydrapod


@pytest.fixture
def master(request):
    """(the emulated hexapod's devices, a canopen network on their channel, its SDO clients)."""
    channel = f"configure-{request.node.name}"
    emulated = CanopenRig("hexapod", channel)
    network = canopen.Network()
    network.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    network.notifier = can.Notifier(network.bus, network.listeners, timeout=0.02)

    def client_of(node: int):
        remote = network.nodes.get(node) or network.add_node(node, canopen.ObjectDictionary())
        remote.sdo.RESPONSE_TIMEOUT, remote.sdo.MAX_RETRIES = 0.2, 1     # one request
        return remote.sdo

    yield emulated, network, client_of
    network.disconnect()
    emulated.close()


def test_a_valves_settings_go_first_then_its_pdos():
    (valve,) = [d for d in load_layout(6) if d.name == "LEG2_VALVE"]
    writes = node_writes(valve)
    assert writes[:5] == [Write(0x1017, 0, 100), Write(0x6042, 0, 1), Write(0x6043, 0, 1), Write(0x6314, 1, 0),
                          Write(0x1400, 5, 6)]                                  # the layout's, in its order
    assert writes[5] == Write(0x1400, 1, 0x202 | COB_ID_INVALID)


def test_the_writes_follow_cia_301_s_order_for_a_remapping():
    (sensors,) = [d for d in load_layout(6) if d.name == "LEG3_LEG_SENSORS"]
    writes = node_writes(sensors)
    tpdo2 = [w for w in writes if w.index in (0x1801, 0x1A01)]
    assert tpdo2[0] == Write(0x1801, 1, (0x280 + sensors.node) | COB_ID_INVALID)      # disabled first
    assert tpdo2[1] == Write(0x1A01, 0, 0)                                          # then no entries
    assert [w.value for w in tpdo2[2:5]] == [0x71300210, 0x71300310, 0x71300410]
    assert tpdo2[5:] == [Write(0x1A01, 0, 3), Write(0x1801, 2, 16), Write(0x1801, 6, 5),   # leg 3's start
                         Write(0x1801, 1, 0x280 + sensors.node)]                   # enabled last


def test_the_layout_configured_and_read_back_is_what_the_devices_then_send(master):
    emulated, network, client_of = master
    devices = load_layout(6)
    configure(client_of, devices)
    node_of = {d.name: d.node for d in devices}
    stored = written_values(emulated.emulator.devices.nodes[node_of["LEG3_LEG_SENSORS"]])
    assert stored[(0x1801, 6)] == 5 and stored[(0x1A01, 0)] == 3 and stored[(0x1017, 0)] == 100
    assert written_values(emulated.emulator.devices.nodes[node_of["LEG4_VALVE"]])[(0x1400, 5)] == 6

    # started, the pressures' TPDO2 of each leg comes at its own SYNCs: legs 1-6 at 1, 3, 5, 9, 11, 13
    heard: dict[int, list[int]] = {}
    counter, ended = [0], []
    for d in devices:
        if d.name.endswith("_LEG_SENSORS"):
            network.subscribe(0x280 + d.node, lambda cob, data, t: heard.setdefault(cob - 0x280, []).append(counter[0]))
    network.subscribe(CODECS["EMU_TRUTH"].frame_id, lambda cob, data, t: ended.append(counter[0]))   # a SYNC's last
    network.nmt.state = "OPERATIONAL"
    for k in range(1, 33):
        counter[0] = k
        network.sync.transmit(k)
        deadline = time.monotonic() + 2.0
        while not (ended and ended[-1] == k):
            assert time.monotonic() < deadline, f"the emulator did not answer SYNC {k}"
            time.sleep(0.002)
    legs = sorted(heard)
    assert legs == [node_of[f"LEG{leg}_LEG_SENSORS"] for leg in range(1, 7)]
    assert [heard[node] for node in legs] == [[s, s + 16] for s in (1, 3, 5, 9, 11, 13)]


def test_a_node_that_is_not_the_device_configured_refuses_in_one_line(master):
    _, _, client_of = master
    wrong = Device("LEG1_VALVE", "canopen-valve.eds", 33, 0, 1)               # node 33 is leg 1's encoder
    with pytest.raises(ConfigurationError) as error:
        configure(client_of, [wrong])
    line = str(error.value)
    assert line.startswith("node 33 (LEG1_VALVE): 0x1400:1 (") and "refused" in line and "\n" not in line


def test_a_silent_node_is_named(master):
    _, _, client_of = master
    with pytest.raises(ConfigurationError, match=r"^node 99 \(LEG9_VALVE\): 0x1400:1 .*: no SDO answer writing"):
        configure(client_of, [Device("LEG9_VALVE", "canopen-valve.eds", 99, 0, 9)])


class _Forgetful:
    """A device that takes every write and reads back its transmission types as 255."""

    def __init__(self, od):
        self.od, self.stored = od, {}

    def download(self, index, sub, data):
        self.stored[(index, sub)] = bytes(data)

    def upload(self, index, sub):
        if sub == 2 and 0x1800 <= index < 0x1A00:
            return (255).to_bytes(1, "little")
        return self.stored[(index, sub)]


def test_a_value_that_reads_back_otherwise_is_named():
    (valve,) = [d for d in load_layout(1) if d.name == "LEG1_VALVE"]
    client = _Forgetful(object_dictionary(valve.eds, valve.node))
    with pytest.raises(ConfigurationError, match=r"^node 1 \(LEG1_VALVE\): 0x1800:2 \(.*\) reads back 0xFF, "
                                                 r"written 0x1: not started$"):
        configure(lambda node: client, [valve])


def test_the_command_configures_a_rig_or_names_the_node_in_one_line(request):
    channel = f"configure-cli-{request.node.name}"
    emulated = CanopenRig("testbench", channel)
    try:
        done = hydrapod("protocol", "configure", "--bus", f"virtual:{channel}", "--rig", "testbench", "--json")
        assert done.returncode == 0, done.stderr
        assert {row["node"] for row in json.loads(done.stdout)["configured"]} == {1, 33, 49}
        wrong = hydrapod("protocol", "configure", "--bus", f"virtual:{channel}", "--rig", "hexapod",
                         "--sdo-timeout-ms", "50")
        assert wrong.returncode == 2 and wrong.stdout == ""
        assert wrong.stderr.strip().count("\n") == 0, wrong.stderr
        assert "protocol configure: node 2 (LEG2_VALVE): 0x1017:0 (Producer heartbeat time): no SDO answer" \
            in wrong.stderr
    finally:
        emulated.close()
