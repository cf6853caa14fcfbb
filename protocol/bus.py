"""One string names a bus everywhere (CLI, config, tests); `open_bus` turns it into a
python-can bus.

Accepted forms:
    socketcan:<interface>              real SocketCAN (can0) or virtual (vcan0)
    udp_multicast:<group>[:<port>]     processes on this host; IPv4 group, or IPv6 in [..]
    virtual:<name>                     in-process only (unit tests)

`udp_multicast` is always opened with hop limit 0 so no frame ever leaves the machine, and
it is made to behave like a CAN controller: a bus does not receive its own frames (IP
multicast loops them back), and a datagram that is not a python-can frame is counted and
dropped instead of raising. It neither orders nor guarantees delivery; the E2E counters
catch that, as on a real bus. Distinct runs on one host should use distinct ports.
"""

from __future__ import annotations

import ipaddress
import os
import re
import select
import socket
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import can
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from program.errors import UserInputError
from protocol import udpfilter

BUS_FORMS = ("socketcan:<interface> | udp_multicast:<group>[:<port>] "
             "| udp_multicast:[<ipv6-group>]:<port> | virtual:<name>")
DEFAULT_MULTICAST_GROUP = "239.255.72.80"   # IPv4 organisation-local scope
DEFAULT_MULTICAST_PORT = 43180
DEFAULT_SOCKETCAN_INTERFACE = "vcan0"
_RCVBUF_BYTES = 4 << 20          # survive bursts while a process is busy; capped by rmem_max
# a recorder may fall behind for seconds (a babbling node at the bus's capacity) and must
# lose nothing: it reads the backlog afterwards (root lifts the rmem_max cap)
RECORDER_RCVBUF_BYTES = 128 << 20
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)
_IP_MULTICAST_ALL = 49           # Linux: 0 = receive only the groups this socket joined
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")     # the kernel's receive timestamp: seconds, nanoseconds
_MAX_DATAGRAM = 4096
_IFNAME = re.compile(r"[A-Za-z0-9_.\-]{1,15}")


class BusSpecError(UserInputError):
    """The bus string is malformed."""


class BusOpenError(UserInputError):
    """The bus string is well-formed but the bus cannot be opened here."""


@dataclass(frozen=True)
class BusSpec:
    kind: str                 # "socketcan" | "udp_multicast" | "virtual"
    channel: str              # interface, multicast group or virtual channel name
    port: int | None = None   # udp_multicast only

    def __str__(self) -> str:
        if self.kind == "udp_multicast":
            group = f"[{self.channel}]" if ":" in self.channel else self.channel
            return f"udp_multicast:{group}:{self.port}"
        return f"{self.kind}:{self.channel}"


def _bad(text: str, why: str) -> BusSpecError:
    return BusSpecError(f"bad bus {text!r}: {why}; accepted forms: {BUS_FORMS}")


def _multicast_group(text: str, group: str) -> str:
    try:
        address = ipaddress.ip_address(group)
    except ValueError:
        raise _bad(text, f"{group!r} is not an IP address") from None
    if not address.is_multicast:
        raise _bad(text, f"{group} is not a multicast group (IPv4 224.0.0.0/4, IPv6 ff00::/8)")
    return str(address)


def _port(text: str, port: str) -> int:
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise _bad(text, f"port {port!r} is not an integer in 1..65535")
    return int(port)


def parse_bus_spec(text: str) -> BusSpec:
    """Parse a bus string; raise `BusSpecError` (one line, lists the forms) if malformed."""
    if not isinstance(text, str) or ":" not in text:
        raise _bad(str(text), "missing '<kind>:'")
    kind, _, rest = text.partition(":")
    if kind == "socketcan":
        if not _IFNAME.fullmatch(rest):
            raise _bad(text, "interface name must be 1-15 characters of letters, digits, '_', '.', '-'")
        return BusSpec("socketcan", rest)
    if kind == "virtual":
        if not rest or any(c.isspace() for c in rest):
            raise _bad(text, "virtual channel name must be non-empty without spaces")
        return BusSpec("virtual", rest)
    if kind == "udp_multicast":
        if rest.startswith("["):                      # [ipv6]:port or [ipv6]
            group, sep, tail = rest[1:].partition("]")
            if not sep:
                raise _bad(text, "unclosed '[' around the IPv6 group")
            if tail and not tail.startswith(":"):
                raise _bad(text, "expected ':<port>' after ']'")
            port = _port(text, tail[1:]) if tail else DEFAULT_MULTICAST_PORT
            return BusSpec("udp_multicast", _multicast_group(text, group), port)
        if rest.count(":") > 1:                       # bare IPv6 group, no port
            return BusSpec("udp_multicast", _multicast_group(text, rest), DEFAULT_MULTICAST_PORT)
        group, sep, port = rest.partition(":")
        port_number = _port(text, port) if sep else DEFAULT_MULTICAST_PORT
        return BusSpec("udp_multicast", _multicast_group(text, group), port_number)
    raise _bad(text, f"unknown bus kind {kind!r}")


def socketcan_available(interface: str) -> bool:
    return _af_can_works() and Path("/sys/class/net", interface).exists()


def _af_can_works() -> bool:
    """Whether this kernel can open a raw CAN socket (Python may know AF_CAN when it cannot)."""
    if not hasattr(socket, "AF_CAN"):
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return True


def default_bus_spec() -> BusSpec:
    """`socketcan:vcan0` where that interface exists, else the on-host multicast group."""
    if socketcan_available(DEFAULT_SOCKETCAN_INTERFACE):
        return BusSpec("socketcan", DEFAULT_SOCKETCAN_INTERFACE)
    return BusSpec("udp_multicast", DEFAULT_MULTICAST_GROUP, DEFAULT_MULTICAST_PORT)


class HostMulticastBus(can.BusABC):
    """python-can's udp_multicast frame format (msgpack, interoperable with its
    `UdpMulticastBus`), as one CAN controller on one host, at a lower cost per frame.

    - hop limit 0: frames are delivered only to sockets on this machine;
    - own frames are not received back (each bus tags what it sends with a random token
      carried in the frame's `channel` field; a datagram bearing it is dropped unparsed);
    - a datagram that is not a python-can frame is counted in `rx_garbage`, not raised;
    - `set_filters` runs in the kernel (a BPF acceptance filter), and python-can checks again;
    - classic CAN only (FD frames are rejected on send and dropped on receive);
    - the receive path reads what is queued without a system call to wait, and waits on
      the socket (select, microsecond timeout) only when the queue is empty.
    """

    def __init__(self, group: str, port: int, receive_buffer_bytes: int = _RCVBUF_BYTES, **kwargs):
        super().__init__(channel=group, **kwargs)
        self._can_protocol = can.CanProtocol.CAN_20
        self.group, self.port = group, port
        self.channel_info = f"udp_multicast:{group}:{port} (hop limit 0)"
        self.rx_garbage = 0
        self._token = f"hydrapod-{os.urandom(8).hex()}"
        self._token_bytes = self._token.encode()
        family = socket.AF_INET6 if ":" in group else socket.AF_INET
        self._socket = _multicast_socket(family, group, port, receive_buffer_bytes)
        self._readable = [self._socket]
        self._destination = (group, port)
        self._cmsg_bytes = socket.CMSG_SPACE(_TIMESPEC.size)
        self._apply_filters(self._filters)

    def _apply_filters(self, filters) -> None:
        """In the kernel (`udpfilter`): frames no filter accepts never wake this process."""
        if hasattr(self, "_socket"):              # BusABC.__init__ sets filters before the socket exists
            udpfilter.attach(self._socket, filters)

    def fileno(self) -> int:
        return self._socket.fileno()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd:
            raise can.CanOperationError("cannot send a CAN FD frame on this classic CAN bus")
        channel = msg.channel
        msg.channel = self._token
        try:
            datagram = pack_message(msg)
        finally:
            msg.channel = channel
        try:
            self._socket.sendto(datagram, self._destination)
        except BlockingIOError:
            # the send buffer is full: wait for room as a blocking send would, up to `timeout`
            if not select.select([], self._readable, [], timeout)[1]:
                raise can.CanOperationError(f"{self.channel_info}: send timed out") from None
            self._socket.sendto(datagram, self._destination)
        except OSError as error:
            raise can.CanOperationError(f"{self.channel_info}: send failed: {error}") from error

    def _recv_internal(self, timeout: float | None):
        deadline = None if timeout is None else time.monotonic() + timeout
        sock = self._socket
        while True:
            try:
                data, ancillary, _, _ = sock.recvmsg(_MAX_DATAGRAM, self._cmsg_bytes)
            except BlockingIOError:                       # the queue is empty: wait for a frame
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0.0:
                    return None, False
                select.select(self._readable, [], [], remaining)
                continue
            except OSError as error:
                raise can.CanOperationError(f"{self.channel_info}: receive failed: {error}") from error
            if self._token_bytes in data:
                continue                                  # our own frame, looped back
            msg = self._frame(data, ancillary)
            if msg is not None:
                return msg, False

    def _frame(self, data: bytes, ancillary) -> can.Message | None:
        """The python-can frame in a datagram (None, counted, if it is not one; None for FD)."""
        replace = {"channel": self.channel_info}
        if ancillary:
            seconds, nanoseconds = _TIMESPEC.unpack_from(ancillary[0][2])
            replace["timestamp"] = seconds + nanoseconds * 1e-9
        try:
            msg = unpack_message(data, replace=replace, check=True)
        except Exception:                                  # any malformed datagram
            self.rx_garbage += 1
            return None
        return None if msg.is_fd else msg

    def shutdown(self) -> None:
        super().shutdown()
        self._socket.close()


def _multicast_socket(family: int, group: str, port: int, receive_buffer_bytes: int) -> socket.socket:
    """A non-blocking UDP socket bound to `port`, in `group`, hop limit 0, with kernel
    receive timestamps and a receive buffer of `receive_buffer_bytes` where allowed."""
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        hops = struct.pack("@I", 0)
        if family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, hops)
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, hops)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
        sock.bind(("", port))
        membership = socket.inet_pton(family, group) + struct.pack("@I", 0)
        if family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_JOIN_GROUP, membership)
    except OSError as error:
        sock.close()
        raise can.CanInitializationError(f"udp_multicast:{group}:{port}: {error}") from error
    if family == socket.AF_INET:
        try:
            sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
        except OSError:
            pass   # best effort: only less isolated
    _grow_receive_buffer(sock, receive_buffer_bytes)
    sock.setblocking(False)
    return sock


def _grow_receive_buffer(sock: socket.socket, receive_buffer_bytes: int) -> None:
    """The socket's receive buffer, as large as allowed (root: the full size)."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_bytes)
    except OSError:
        pass   # best effort: the default still works, only less buffered
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_RCVBUFFORCE, receive_buffer_bytes)
    except OSError:
        pass   # not root: SO_RCVBUF's size, capped by rmem_max


def open_bus(spec: str | BusSpec | None = None, recorder: bool = False) -> can.BusABC:
    """Open the bus named by `spec` (None: `default_bus_spec()`); `recorder`: the socket gets
    RECORDER_RCVBUF_BYTES of receive buffer (SocketCAN and multicast alike), so a host that
    falls behind loses nothing.

    Raises `BusSpecError` for a malformed string and `BusOpenError` (one line, naming
    the bus) when it cannot be opened here.
    """
    if spec is None:
        spec = default_bus_spec()
    elif isinstance(spec, str):
        spec = parse_bus_spec(spec)
    try:
        if spec.kind == "socketcan":
            if not _af_can_works():
                raise BusOpenError(f"{spec}: this kernel has no SocketCAN (AF_CAN unsupported); "
                                   f"use udp_multicast:<group> on one host, or run inside a VM")
            if not Path("/sys/class/net", spec.channel).exists():
                raise BusOpenError(f"{spec}: no such network interface (create it: "
                                   f"ip link add dev {spec.channel} type vcan; ip link set up {spec.channel})")
            bus = can.Bus(interface="socketcan", channel=spec.channel, receive_own_messages=False)
            _grow_receive_buffer(bus.socket, RECORDER_RCVBUF_BYTES if recorder else _RCVBUF_BYTES)
            return bus
        if spec.kind == "udp_multicast":
            return HostMulticastBus(spec.channel, spec.port,
                                    RECORDER_RCVBUF_BYTES if recorder else _RCVBUF_BYTES)
        if spec.kind == "virtual":
            return can.Bus(interface="virtual", channel=spec.channel, receive_own_messages=False)
    except (can.CanError, OSError) as error:
        raise BusOpenError(f"{spec}: cannot open: {error}") from error
    raise BusSpecError(f"bad bus {str(spec)!r}: unknown kind; accepted forms: {BUS_FORMS}")
