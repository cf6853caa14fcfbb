"""The devices' EDS files and their SDO servers, held against canopen's own client."""

import can
import canopen
import pytest

from program.errors import UserInputError
from protocol.devices import identity_of, local_node


def test_the_shipped_devices_say_what_they_are():
    leg, imu = identity_of("hydrapod-leg.eds"), identity_of("hydrapod-imu.eds")
    assert leg.device_type & 0xFFFF == 408                     # CiA 408: fluid power
    assert imu.device_type == 0                                # no standard profile
    assert leg.vendor_id == imu.vendor_id == 0x48594450
    assert leg.product_code != imu.product_code


def test_a_local_node_answers_canopen_s_client_with_its_eds_identity():
    server, client = canopen.Network(), canopen.Network()
    for network in (server, client):                 # canopen's connect, its notifier quick to stop
        network.bus = can.Bus(interface="virtual", channel="devices-test", receive_own_messages=False)
        network.notifier = can.Notifier(network.bus, network.listeners, timeout=0.02)
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
