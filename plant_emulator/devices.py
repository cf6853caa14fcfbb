"""The emulated nodes' object dictionaries: each node's from its EDS (`protocol.devices`),
answering SDO as the device would, with canopen's `LocalNode` as the SDO server. What the
controller reads before it starts a node (firmware_py/runtime/identify.py)."""

from __future__ import annotations

import can
import canopen

from protocol.codec import STANDARD_ID_MASK
from protocol.devices import SDO_REQUEST_BASE, local_node
from protocol.nodes import IMU_NODE


class _Sender:
    """canopen's network sends through the emulator's own transmit path."""

    def __init__(self, send):
        self.send = send


class EmulatedDevices:
    def __init__(self, nodes: list[int], leg_eds: str, imu_eds: str, send):
        self.network = canopen.Network(_Sender(lambda msg, timeout=None: send(msg)))
        self.nodes = {}
        for node in nodes:
            self.nodes[node] = local_node(node, imu_eds if node == IMU_NODE else leg_eds)
            self.network.add_node(self.nodes[node])
        self._request = {SDO_REQUEST_BASE + node: node for node in nodes}

    def node_of(self, frame_id: int) -> int | None:
        """The node an SDO request is for (None: not an SDO request to these nodes)."""
        return self._request.get(frame_id)

    def answer(self, msg: can.Message) -> None:
        """An SDO request to one of the nodes: its server answers on the bus."""
        self.network.notify(msg.arbitration_id, bytearray(msg.data), msg.timestamp)

    def can_filters(self) -> list[dict]:
        return [{"can_id": frame_id, "can_mask": STANDARD_ID_MASK, "extended": False} for frame_id in self._request]
