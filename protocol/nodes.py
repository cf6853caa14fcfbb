"""The bus's nodes and their CANopen node ids, from the DBC (`BU_` with the `NodeId`
attribute): legs 1-6 (a CiA 408 valve driver with the leg's sensors), the IMU, the
controller. The host and the emulator's own frames have no node id.
"""

from __future__ import annotations

from program.sections import Key
from protocol.dbc import load_database

HEARTBEAT = Key("heartbeat_ms", 10.0, 10000.0, 1e-3)               # a node's heartbeat producer time


def _node_ids() -> dict[str, int]:
    out = {}
    for node in load_database().nodes:
        attribute = node.dbc.attributes.get("NodeId") if node.dbc is not None else None
        if attribute is not None and attribute.value:
            out[node.name] = int(attribute.value)
    return out


NODE_IDS: dict[str, int] = _node_ids()          # sender name in the DBC -> node id
SENDER_OF_NODE: dict[int, str] = {node: name for name, node in NODE_IDS.items()}
CONTROLLER_NODE = NODE_IDS["CONTROLLER"]
IMU_NODE = NODE_IDS["IMU"]
LEG_NODES: tuple[int, ...] = tuple(sorted(node for name, node in NODE_IDS.items() if name.startswith("LEG")))
# the emulator's nodes on a rig with n legs: its legs, and the IMU on the hexapod
HOST_SENDER = "HOST"
EMULATOR_SENDER = "EMULATOR"


# the rigs: the test bench's one leg node, the hexapod's six and its IMU
LEGS_OF_RIG = {"testbench": 1, "hexapod": len(LEG_NODES)}
RIGS = tuple(LEGS_OF_RIG)


def leg_sender(leg: int) -> str:
    """The DBC's sender name of leg `leg` (1-based)."""
    return SENDER_OF_NODE[LEG_NODES[leg - 1]]


def rig_nodes(n_legs: int) -> list[int]:
    """Node ids a rig with `n_legs` legs has on the bus: its legs, and the IMU on the hexapod."""
    return list(LEG_NODES[:n_legs]) + ([IMU_NODE] if n_legs == len(LEG_NODES) else [])
