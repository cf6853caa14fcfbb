"""The emulated nodes' object dictionaries: each node's from its EDS (`protocol.devices`),
answering SDO as the device would, with canopen's `LocalNode` as the SDO server. What the
controller reads before it starts a node (firmware_py/runtime/identify.py)."""

from __future__ import annotations

import can
import canopen

from protocol.codec import STANDARD_ID_MASK
from protocol.devices import SDO_REQUEST_BASE, local_node


class _Sender:
    """canopen's network sends through the emulator's own transmit path."""

    def __init__(self, send):
        self.send = send


class EmulatedDevices:
    """`eds_of` node id -> its EDS: each node's SDO server."""

    def __init__(self, eds_of: dict[int, str], send):
        self.network = canopen.Network(_Sender(lambda msg, timeout=None: send(msg)))
        self.eds_of = dict(eds_of)
        self.nodes = {}
        for node in self.eds_of:
            self.reset(node)
        self._request = {SDO_REQUEST_BASE + node: node for node in self.eds_of}

    def reset(self, node: int) -> canopen.LocalNode:
        """The node as it powers up: its EDS's defaults, nothing a master wrote."""
        self.nodes[node] = local_node(node, self.eds_of[node])
        self.network.add_node(self.nodes[node])          # replaces the node before, unsubscribed
        return self.nodes[node]

    def node_of(self, frame_id: int) -> int | None:
        """The node an SDO request is for (None: not an SDO request to these nodes)."""
        return self._request.get(frame_id)

    def answer(self, msg: can.Message) -> None:
        """An SDO request to one of the nodes: its server answers on the bus."""
        self.network.notify(msg.arbitration_id, bytearray(msg.data), msg.timestamp)

    def can_filters(self) -> list[dict]:
        return [{"can_id": frame_id, "can_mask": STANDARD_ID_MASK, "extended": False} for frame_id in self._request]
