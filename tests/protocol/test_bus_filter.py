"""The on-host bus's kernel acceptance filter (`protocol.udpfilter`): python-can's own
filter rule (`BusABC._matches_filters`, the oracle) decides, for random filters and frames,
what the kernel lets through; what is not a python-can frame still reaches the bus."""

import socket
import time

import can
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.bus import open_bus
from protocol.codec import CODECS, FrameDecoder
from protocol.udpfilter import acceptance_program
from tests.support.buses import GROUP, free_port, opened

SENTINEL = {"can_id": 0x1FFFFFFF, "can_mask": 0x1FFFFFFF, "extended": True}

# ids in every msgpack form the frame format takes: fixint, uint8, uint16, uint32
ids = st.one_of(st.integers(0, 0x7F), st.integers(0x80, 0xFF), st.integers(0x100, 0x7FF),
                st.integers(0x800, 0x1FFFFFFE))
filters = st.lists(st.fixed_dictionaries(
    {"can_id": ids, "can_mask": st.one_of(st.just(0x7FF), st.just(0x1FFFFFFF), st.integers(0, 0x1FFFFFFF))},
    optional={"extended": st.booleans()}), min_size=1, max_size=6)
frames = st.lists(st.tuples(ids, st.booleans()), min_size=1, max_size=20)


def _until_sentinel(bus) -> list[tuple[int, bool]]:
    """Frames the kernel let through, read below python-can's software filter."""
    got, deadline = [], time.monotonic() + 1.0      # loopback: queued before send() returns
    while time.monotonic() < deadline:
        msg, _ = bus._recv_internal(0.2)
        if msg is None:
            continue
        if msg.arbitration_id == SENTINEL["can_id"]:
            return got
        got.append((msg.arbitration_id, msg.is_extended_id))
    raise AssertionError("the sentinel frame never arrived")


@settings(max_examples=60)
@given(chosen=filters, sent=frames)
def test_the_kernel_passes_what_python_cans_filters_match(chosen, sent):
    port = free_port()
    with opened(f"udp_multicast:{GROUP}:{port}", f"udp_multicast:{GROUP}:{port}") as (tx, rx):
        rx.set_filters(chosen + [SENTINEL])
        oracle = can.Bus(interface="virtual", channel="filter-oracle", can_filters=chosen + [SENTINEL])
        expected = []
        for ident, extended in sent:
            extended = extended or ident > 0x7FF
            msg = can.Message(arbitration_id=ident, data=b"\x01", is_extended_id=extended)
            tx.send(msg)
            if oracle._matches_filters(msg):
                expected.append((ident, extended))
        oracle.shutdown()
        tx.send(can.Message(arbitration_id=SENTINEL["can_id"], data=b"", is_extended_id=True))
        assert _until_sentinel(rx) == expected


def test_what_is_not_a_frame_passes_the_filter_and_is_counted():
    port = free_port()
    with opened(f"udp_multicast:{GROUP}:{port}", f"udp_multicast:{GROUP}:{port}") as (tx, rx):
        rx.set_filters([SENTINEL])
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            for datagram in (b"short", bytes(300), b"\x8b" + bytes(120)):
                raw.sendto(datagram, (GROUP, port))
        tx.send(can.Message(arbitration_id=0x181, data=b"", is_extended_id=False))       # filtered out
        tx.send(can.Message(arbitration_id=SENTINEL["can_id"], data=b"", is_extended_id=True))
        assert _until_sentinel(rx) == [] and rx.rx_garbage == 3


def test_no_filters_let_every_frame_through_again():
    port = free_port()
    with opened(f"udp_multicast:{GROUP}:{port}", f"udp_multicast:{GROUP}:{port}") as (tx, rx):
        rx.set_filters([SENTINEL])
        rx.set_filters(None)
        tx.send(can.Message(arbitration_id=0x181, data=b"", is_extended_id=False))
        tx.send(can.Message(arbitration_id=SENTINEL["can_id"], data=b"", is_extended_id=True))
        assert _until_sentinel(rx) == [(0x181, False)]


def test_a_nodes_filters_are_its_decoders_messages():
    names = ["SYNC", "VALVE_CMD_1", "EMU_CTRL"]
    chosen = FrameDecoder(names).can_filters()
    assert [f["can_id"] for f in chosen] == [CODECS[n].frame_id for n in names]
    assert all(f["can_mask"] == 0x7FF and f["extended"] is False for f in chosen)
    # the program's conditional jumps are short (8-bit offsets): a node's whole DBC fits
    program = acceptance_program(FrameDecoder().can_filters())
    assert all(jt < 256 and jf < 256 for _, jt, jf, _ in program) and len(program) < 4096


def test_a_filtered_bus_still_reads_its_frames_from_python_cans_own_udp_multicast():
    from can.interfaces.udp_multicast import UdpMulticastBus
    port = free_port()
    ours = open_bus(f"udp_multicast:{GROUP}:{port}")
    stock = UdpMulticastBus(channel=GROUP, port=port, hop_limit=0, fd=False)
    try:
        ours.set_filters([{"can_id": 0x182, "can_mask": 0x7FF, "extended": False}])
        for ident in (0x181, 0x182):
            stock.send(can.Message(arbitration_id=ident, data=b"\x05", is_extended_id=False))
        got = ours.recv(1.0)
        assert got is not None and got.arbitration_id == 0x182 and ours.recv(0.1) is None
    finally:
        stock.shutdown()
        ours.shutdown()
