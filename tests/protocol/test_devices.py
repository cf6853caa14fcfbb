"""The devices' EDS files and their SDO servers, held against canopen's own client."""

import can
import canopen
import pytest

from program.errors import UserInputError
from protocol.devices import device_file, identity_of, local_node, written_values
from protocol.pdo import TPDO, pdo_maps


def _networks(channel: str):
    server, client = canopen.Network(), canopen.Network()
    for network in (server, client):                 # canopen's connect, its notifier quick to stop
        network.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        network.notifier = can.Notifier(network.bus, network.listeners, timeout=0.02)
    return server, client


def test_the_shipped_devices_say_what_they_are():
    leg, imu = identity_of("hydrapod-leg.eds"), identity_of("hydrapod-imu.eds")
    assert leg.device_type & 0xFFFF == 408                     # CiA 408: fluid power
    assert imu.device_type == 0                                # no standard profile
    assert leg.vendor_id == imu.vendor_id == 0x48594450
    assert leg.product_code != imu.product_code


def test_a_local_node_answers_canopen_s_client_with_its_eds_identity():
    server, client = _networks("devices-test")
    try:
        server.add_node(local_node(3, "hydrapod-leg.eds"))
        remote = client.add_node(3, canopen.ObjectDictionary())
        expected = identity_of("hydrapod-leg.eds")
        read = [int.from_bytes(remote.sdo.upload(index, sub), "little")
                for index, sub in ((0x1000, 0), (0x1018, 1), (0x1018, 2), (0x1018, 3))]
        assert read == [expected.device_type, expected.vendor_id, expected.product_code, expected.revision]
        with pytest.raises(canopen.SdoAbortedError):
            remote.sdo.upload(0x6300, 0)                       # not in this dictionary
    finally:
        server.disconnect()
        client.disconnect()


def test_a_missing_or_unreadable_eds_is_one_line(tmp_path):
    with pytest.raises(UserInputError, match="nope.eds: no such EDS file"):
        identity_of("nope.eds")
    bad = tmp_path / "bad.eds"
    bad.write_text("[DeviceInfo]\nVendorNumber=1\n")
    with pytest.raises(UserInputError, match="bad.eds"):
        identity_of(str(bad))


def test_a_master_remaps_a_stock_valves_pdo_by_sdo_and_reads_it_back():
    """canopen's own PDO API (read, clear, add_variable, save) against the emulated valve: the
    mapping it writes is the one the device then carries (`written_values`, `pdo_maps`)."""
    server, client = _networks("remap-test")
    try:
        local = server.add_node(local_node(2, "canopen-valve.eds"))
        remote = client.add_node(2, str(device_file("canopen-valve.eds")))
        remote.tpdo.read()
        assert [(v.index, v.subindex) for v in remote.tpdo[1].map] == [(0x6041, 0), (0x6301, 1)]
        remote.tpdo[1].clear()
        remote.tpdo[1].add_variable(0x6301, 1)
        remote.tpdo[1].trans_type = 2
        remote.tpdo[1].enabled = True
        remote.tpdo.save()
        remote.tpdo.read()
        assert [(v.index, v.subindex) for v in remote.tpdo[1].map] == [(0x6301, 1)] and remote.tpdo[1].trans_type == 2
        (carried,) = pdo_maps(local.object_dictionary, TPDO, "LEG2_VALVE", written_values(local))
        assert carried.entries() == ((0x6301, 1),) and carried.sync_period == 2 and carried.cob_id == 0x182
    finally:
        server.disconnect()
        client.disconnect()


@pytest.mark.parametrize("entries, abort", [([0x10170010], 0x06040041),          # the heartbeat: not mappable
                                            ([0x20000010], 0x06040041),          # no such object
                                            ([0x60410010] * 3, 0x06090031)])     # it has two entries
def test_a_mapping_the_valve_cannot_carry_is_refused_with_cia_301_s_abort(entries, abort):
    server, client = _networks(f"refuse-test-{abort}-{entries[0]}")
    try:
        local = server.add_node(local_node(2, "canopen-valve.eds"))
        remote = client.add_node(2, canopen.ObjectDictionary())
        remote.sdo.download(0x1800, 1, (0x80000182).to_bytes(4, "little"))      # disabled, as CiA 301 asks
        remote.sdo.download(0x1A00, 0, bytes([0]))
        for sub, entry in enumerate(entries[:2], start=1):
            remote.sdo.download(0x1A00, sub, entry.to_bytes(4, "little"))
        with pytest.raises(canopen.SdoAbortedError) as error:
            remote.sdo.download(0x1A00, 0, bytes([len(entries)]))
        assert error.value.code == abort
        assert written_values(local)[(0x1A00, 0)] == 0                          # still none mapped
    finally:
        server.disconnect()
        client.disconnect()
