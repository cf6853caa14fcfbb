"""Identify before starting: no NMT start and no valve command to a node whose device type
(0x1000) and identity (0x1018: vendor, product) are not those of the EDS configured for its
node id (`protocol.devices`). Read by SDO with the `canopen` library's client, on the loop's
own bus and thread: while it waits for an answer it hands every other frame to the loop
(heartbeats, EMCY), so nothing the nodes say meanwhile is lost.
"""

from __future__ import annotations

import canopen
from canopen.sdo.client import SdoClient
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from protocol.devices import CHECKED, REVISION, SDO_REQUEST_BASE, SDO_RESPONSE_BASE, Identity, canopen_log_quiet
from protocol.nodes import SENDER_OF_NODE


class IdentityError(RuntimeError):
    """A node is not the device configured for it, or did not say what it is."""


class _LoopSdoClient(SdoClient):
    """canopen's SDO client, its wait for an answer done by receiving on the loop's bus."""

    MAX_RETRIES = 1                               # one request; a silent node is named, not retried

    def __init__(self, node: int, network: canopen.Network, receive, dispatch, clock, timeout_s: float):
        super().__init__(SDO_REQUEST_BASE + node, SDO_RESPONSE_BASE + node, canopen.ObjectDictionary())
        self.network = network
        self._receive, self._dispatch, self._clock, self._timeout_s = receive, dispatch, clock, timeout_s

    def read_response(self):
        deadline = self._clock() + self._timeout_s
        while self.responses.empty() and self._clock() < deadline:
            msg = self._receive(min(0.01, max(deadline - self._clock(), 0.0)))
            if msg is None:
                continue
            if msg.arbitration_id == self.tx_cobid and not msg.is_extended_id:
                self.on_response(msg.arbitration_id, msg.data, msg.timestamp)
            else:
                self._dispatch(msg)
        return super().read_response()           # the answer, an abort, or "no SDO response"


def loop_sdo_clients(bus, receive, dispatch, clock, timeout_s: float):
    """`client_of(node)`: canopen's SDO client to `node`, sending on `bus` and waiting for its
    answer by `receive(timeout_s)`, every other frame meanwhile handed to `dispatch`."""
    network = canopen.Network(bus)               # sends on the loop's bus; no listener of its own
    return lambda node: _LoopSdoClient(node, network, receive, dispatch, clock, timeout_s)


def node_name(node: int, names: dict[int, str] | None = None) -> str:
    return f"node {node} ({(names or SENDER_OF_NODE).get(node, '?')})"


def read_identity(client: SdoClient, node: int, names: dict[int, str] | None = None) -> Identity:
    """The node's device type, vendor, product and revision, by SDO; one line naming the node
    and the object it could not read (IdentityError)."""
    values = {}
    for name, (index, sub) in (*CHECKED, ("revision", REVISION)):
        try:
            data = client.upload(index, sub)
        except SdoAbortedError as error:
            if name == "revision":               # optional in 0x1018
                values[name] = 0
                continue
            raise IdentityError(f"{node_name(node, names)}: reading its {name} (0x{index:04X}:{sub}) was aborted: "
                                f"{error}") from None
        except SdoCommunicationError:
            raise IdentityError(f"{node_name(node, names)}: no SDO answer reading its {name} (0x{index:04X}:{sub}) "
                                f"within {client._timeout_s * 1e3:g} ms") from None
        values[name] = int.from_bytes(bytes(data[:4]), "little")
    return Identity(values["device type"], values["vendor id"], values["product code"], values["revision"])


def check(node: int, found: Identity, expected: Identity, eds: str, names: dict[int, str] | None = None) -> None:
    """One line naming the node, the object and both values when `found` is not `expected`."""
    for name, (index, sub) in CHECKED:
        if found.value(name) != expected.value(name):
            raise IdentityError(f"{node_name(node, names)}: {name} (0x{index:04X}:{sub}) is 0x{found.value(name):08X}, "
                                f"{eds} says 0x{expected.value(name):08X}: not started")


def identify(client_of, expected: dict[int, tuple[Identity, str]],
             names: dict[int, str] | None = None) -> dict[int, Identity]:
    """Every node's identity read through `client_of(node)` and checked against `expected`
    (node -> (identity, its EDS)); the identities read, or IdentityError for the first node
    that differs or is silent (`names`: node -> the device's name, for that line)."""
    found = {}
    with canopen_log_quiet():                    # a silent node: our one line, not canopen's log too
        for node, (identity, eds) in expected.items():
            found[node] = read_identity(client_of(node), node, names)
            check(node, found[node], identity, eds, names)
    return found
