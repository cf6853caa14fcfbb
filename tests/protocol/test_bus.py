"""Bus strings, opening, and the on-host multicast bus between real OS processes."""

import json
import os
import socket
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import can
import pytest

from protocol.bus import (
    BUS_FORMS,
    RECORDER_RCVBUF_BYTES,
    BusOpenError,
    BusSpec,
    BusSpecError,
    HostMulticastBus,
    default_bus_spec,
    open_bus,
    parse_bus_spec,
    socketcan_available,
)
from protocol.codec import CODECS, FrameDecoder
from protocol.e2e import RxStatus
from tests.support import bus_peer
from tests.support.buses import GROUP, free_port, opened


@pytest.mark.parametrize("text, spec", [
    ("socketcan:vcan0", BusSpec("socketcan", "vcan0")),
    ("socketcan:can0", BusSpec("socketcan", "can0")),
    ("udp_multicast:239.255.72.80", BusSpec("udp_multicast", "239.255.72.80", 43180)),
    ("udp_multicast:239.255.72.80:5000", BusSpec("udp_multicast", "239.255.72.80", 5000)),
    ("udp_multicast:[ff15::7]:6000", BusSpec("udp_multicast", "ff15::7", 6000)),
    ("udp_multicast:ff15::7", BusSpec("udp_multicast", "ff15::7", 43180)),
    ("virtual:unit", BusSpec("virtual", "unit")),
])
def test_good_specs_parse_and_print_back(text, spec):
    assert parse_bus_spec(text) == spec
    assert parse_bus_spec(str(spec)) == spec


@pytest.mark.parametrize("text, culprit", [
    ("vcan0", "missing"), ("can:vcan0", "'can'"), ("socketcan:", "interface"),
    ("socketcan:a/b", "interface"), ("socketcan:waytoolonginterface", "interface"),
    ("udp_multicast:10.1.2.3", "not a multicast"), ("udp_multicast:239.1.2.3:0", "port"),
    ("udp_multicast:239.1.2.3:70000", "port"), ("udp_multicast:239.1.2.3:x", "port"),
    ("udp_multicast:nohost", "not an IP"), ("udp_multicast:[ff15::1", "unclosed"),
    ("virtual:", "name"), ("", "missing"),
])
def test_bad_specs_give_one_line_listing_the_forms(text, culprit):
    with pytest.raises(BusSpecError) as err:
        parse_bus_spec(text)
    message = str(err.value)
    assert "\n" not in message and culprit in message and BUS_FORMS in message


def test_default_is_vcan0_when_present_else_on_host_multicast():
    spec = default_bus_spec()
    if socketcan_available("vcan0"):
        assert spec == BusSpec("socketcan", "vcan0")
    else:
        assert spec.kind == "udp_multicast" and parse_bus_spec(str(spec)) == spec


def test_socketcan_opens_where_available_else_one_clear_line():
    if socketcan_available("vcan0"):
        bus = open_bus("socketcan:vcan0")
        bus.shutdown()
    else:
        with pytest.raises(BusOpenError) as err:
            open_bus("socketcan:vcan0")
        assert "\n" not in str(err.value) and "socketcan:vcan0" in str(err.value)


def test_virtual_bus_in_process():
    with opened("virtual:test-virtual", "virtual:test-virtual") as (a, b):
        codec = CODECS["VALVE_CMD_3"]
        msg = can.Message(arbitration_id=codec.frame_id, data=codec.new_buffer(), is_extended_id=False)
        decoder = FrameDecoder(["VALVE_CMD_3"])
        for _ in range(20):
            codec.encode_into(codec.new_values(), msg.data)
            a.send(msg)
            assert decoder.receive_message(b.recv(1.0)) is RxStatus.OK
        assert a.recv(0.05) is None                      # no own frames, like a CAN controller


def test_multicast_is_hop_limit_zero_and_drops_own_and_garbage():
    port = free_port()
    with opened(f"udp_multicast:{GROUP}:{port}", f"udp_multicast:{GROUP}:{port}") as (a, b):
        assert isinstance(a, HostMulticastBus)
        with socket.fromfd(a.fileno(), socket.AF_INET, socket.SOCK_DGRAM) as s:
            assert s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0   # never leaves the host
        a.send(can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False))
        got = b.recv(1.0)
        assert got is not None and got.arbitration_id == 0x181 and bytes(got.data) == b"\x01\x02"
        assert a.recv(0.1) is None
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            raw.sendto(b"not a frame", (GROUP, port))
        a.send(can.Message(arbitration_id=0x182, data=b"", is_extended_id=False))
        got = b.recv(1.0)
        assert got is not None and got.arbitration_id == 0x182 and b.rx_garbage == 1


def test_multicast_groups_on_one_port_are_isolated():
    port = free_port()
    specs = (f"udp_multicast:{GROUP}:{port}", f"udp_multicast:{GROUP}:{port}", f"udp_multicast:239.255.72.81:{port}")
    with opened(*specs) as (a, b, other):
        a.send(can.Message(arbitration_id=0x100, data=b"", is_extended_id=False))
        assert b.recv(1.0) is not None
        assert other.recv(0.2) is None


@pytest.mark.process
def test_two_processes_exchange_10k_frames_none_lost_or_reordered():
    """SYNC -> 6 LEG_STATE from the peer process -> 6 VALVE_CMD back, 770 cycles = 10,010 frames.

    The bus is a fresh on-host multicast group unless HYDRAPOD_TEST_BUS names another
    (e.g. socketcan:vcan0 inside a VM with SocketCAN)."""
    cycles = 770
    spec = os.environ.get("HYDRAPOD_TEST_BUS") or f"udp_multicast:{GROUP}:{free_port()}"
    bus = open_bus(spec)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).parents[2]), *sys.path]))
    peer = subprocess.Popen([sys.executable, str(Path(bus_peer.__file__)), spec, str(cycles)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 60
        while True:                                      # handshake: the peer says READY
            msg = bus.recv(1.0)
            if msg is not None and msg.arbitration_id == bus_peer.READY_ID:
                break
            assert time.monotonic() < deadline and peer.poll() is None, peer.stderr.read() if peer.poll() else ""
        legs = range(1, 7)
        sync = can.Message(arbitration_id=CODECS["SYNC"].frame_id, data=bytearray(1), is_extended_id=False)
        sync_values = CODECS["SYNC"].new_values()
        cmds = {n: can.Message(arbitration_id=CODECS[f"VALVE_CMD_{n}"].frame_id, data=bytearray(4),
                               is_extended_id=False) for n in legs}
        cmd_values = CODECS["VALVE_CMD_1"].new_values()
        spool = CODECS["VALVE_CMD_1"].index["SPOOL_SETPOINT"]
        decoder = FrameDecoder([f"LEG_STATE_{n}" for n in legs])
        position = CODECS["LEG_STATE_1"].index["POSITION"]
        received = 0
        for k in range(cycles):
            sync_values[0] = bus_peer.sync_counter_of(k)
            CODECS["SYNC"].encode_into(sync_values, sync.data)
            bus.send(sync)
            for n in legs:                               # exactly LEG_STATE_1..6 in order
                msg = bus.recv(5.0)
                while k == 0 and msg is not None and msg.arbitration_id == bus_peer.READY_ID:
                    msg = bus.recv(5.0)                  # READYs sent before our first SYNC arrived
                assert msg is not None, f"cycle {k}: LEG_STATE_{n} lost"
                received += 1
                assert msg.arbitration_id == CODECS[f"LEG_STATE_{n}"].frame_id, f"cycle {k}: reordered"
                assert decoder.receive_message(msg) is RxStatus.OK
                assert decoder.values[f"LEG_STATE_{n}"][position] == pytest.approx(bus_peer.position_of(k))
            for n in legs:
                cmd_values[spool] = bus_peer.spool_of(k, n)
                CODECS[f"VALVE_CMD_{n}"].encode_into(cmd_values, cmds[n].data)
                bus.send(cmds[n])
        bus.send(can.Message(arbitration_id=bus_peer.FIN_ID, data=b"", is_extended_id=False))
        out, err = peer.communicate(timeout=60)
        assert peer.returncode == 0, err
        summary = json.loads(out)
        assert summary["errors"] == [] and summary["cycles"] == cycles and summary["lost"] == 0
        assert summary["received"] == 7 * cycles                 # SYNC + 6 commands per cycle
        assert received + summary["received"] == 13 * cycles >= 10_000
        assert decoder.lost.sum() == 0 and decoder.counts[:, RxStatus.OK].sum() == 6 * cycles
    finally:
        if peer.poll() is None:
            peer.kill()
            peer.wait()
        bus.shutdown()


def _receive_buffer(bus) -> int:
    with socket.fromfd(bus.fileno(), socket.AF_INET, socket.SOCK_DGRAM) as sock:
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


def test_the_recorder_gets_a_receive_buffer_for_a_backlog_of_seconds():
    spec = "udp_multicast:239.255.61.3:40877"
    with ExitStack() as stack:
        node = open_bus(spec)
        stack.callback(node.shutdown)
        recorder = open_bus(spec, recorder=True)
        stack.callback(recorder.shutdown)
        # the kernel reports twice the size asked for (its bookkeeping)
        if os.geteuid() == 0:
            assert _receive_buffer(recorder) >= RECORDER_RCVBUF_BYTES > _receive_buffer(node) // 2
        else:
            assert _receive_buffer(recorder) >= _receive_buffer(node)


def test_multicast_frames_interoperate_with_python_cans_own_udp_multicast():
    """The frame format is python-can's: its stock bus (the oracle) and ours read each other."""
    from can.interfaces.udp_multicast import UdpMulticastBus
    port = free_port()
    ours = open_bus(f"udp_multicast:{GROUP}:{port}")
    stock = UdpMulticastBus(channel=GROUP, port=port, hop_limit=0, fd=False)
    try:
        frames = ((0x181, b"\x01\x02\x03", False), (0x1ABCDEF, b"", True), (0x7FE, bytes(8), False))
        for ident, data, extended in frames:
            ours.send(can.Message(arbitration_id=ident, data=data, is_extended_id=extended))
            got = stock.recv(1.0)
            while got is not None and got.arbitration_id != ident:     # the stock bus hears itself
                got = stock.recv(1.0)
            assert (got.arbitration_id, bytes(got.data), got.is_extended_id) == (ident, data, extended)
            assert got.dlc == len(data)
            stock.send(can.Message(arbitration_id=ident + 1, data=data, is_extended_id=extended))
            got = ours.recv(1.0)
            assert (got.arbitration_id, bytes(got.data), got.is_extended_id) == (ident + 1, data, extended)
            assert abs(got.timestamp - time.time()) < 5.0          # the kernel's receive time
        with pytest.raises(can.CanOperationError):
            ours.send(can.Message(arbitration_id=0x100, data=bytes(12), is_fd=True))
        stock_fd = UdpMulticastBus(channel=GROUP, port=port, hop_limit=0, fd=True)
        try:
            stock_fd.send(can.Message(arbitration_id=0x100, data=bytes(12), is_fd=True))
            assert ours.recv(0.2) is None and ours.rx_garbage == 0     # FD: dropped, not garbage
        finally:
            stock_fd.shutdown()
    finally:
        stock.shutdown()
        ours.shutdown()
