"""Who answers at a node id: each device's object dictionary from its EDS (CiA 306), read
with the `canopen` library, and the identity the controller checks by SDO before it starts
a node (CiA 301: device type 0x1000, identity 0x1018).

The emulated devices' EDS files live here (`hydrapod-leg.eds`, `hydrapod-imu.eds`); on a rig
the configuration names the vendor's. A device's identity is its EDS's: the device type is
0x1000's default value, the vendor and product are [DeviceInfo]'s VendorNumber and
ProductNumber (an EDS often leaves 0x1018's defaults empty: the device fills them in).
SDO frames (0x600 + node to the node, 0x580 + node back) are CiA 301's and not in the DBC.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import canopen
from canopen.objectdictionary.datatypes import INTEGER_TYPES

from program.errors import UserInputError
from program.sections import STR, Key
from protocol.pdo import SDO_ABORT_TOO_HIGH, SDO_ABORT_TOO_LOW, mapping_write_abort

DEVICES_DIR = Path(__file__).parent
DEVICE_PROFILES = ("hydrapod", "canopen")   # the project's DBC nodes, or stock CANopen devices
SDO_REQUEST_BASE = 0x600                 # client -> server (the node's SDO server receives)
SDO_RESPONSE_BASE = 0x580                # server -> client
EMCY_BASE = 0x80                         # a node's EMCY at 0x80 + its id (CiA 301)
HEARTBEAT_BASE = 0x700                   # its heartbeat (NMT error control) at 0x700 + its id
DEVICE_TYPE = (0x1000, 0)
VENDOR_ID = (0x1018, 1)
PRODUCT_CODE = (0x1018, 2)
REVISION = (0x1018, 3)
# what must match before a node is started, in the order read (the revision is reported only)
CHECKED = (("device type", DEVICE_TYPE), ("vendor id", VENDOR_ID), ("product code", PRODUCT_CODE))
# the configuration's keys naming each kind of node's EDS (controller: what it expects;
# emulator: what it emulates)
LEG_EDS = Key("leg_eds", kind=STR)
IMU_EDS = Key("imu_eds", kind=STR)


@dataclass(frozen=True)
class Identity:
    device_type: int
    vendor_id: int
    product_code: int
    revision: int

    def value(self, name: str) -> int:
        return {"device type": self.device_type, "vendor id": self.vendor_id, "product code": self.product_code,
                "revision": self.revision}[name]


@contextmanager
def canopen_log_quiet():
    """canopen's own log (the abort it sends after a timeout) kept off stderr meanwhile: the
    caller's one line says what failed."""
    log = logging.getLogger("canopen")
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)


def device_file(name: str) -> Path:
    """An EDS by file name (shipped here) or path; a missing one is one line (UserInputError)."""
    path = Path(name)
    if not path.is_absolute() and not path.exists():
        path = DEVICES_DIR / name
    if not path.is_file():
        raise UserInputError(f"{name}: no such EDS file (looked in {DEVICES_DIR} too)")
    return path


@cache
def object_dictionary(name: str, node_id: int | None = None) -> canopen.ObjectDictionary:
    """The device's object dictionary (`node_id` resolves the EDS's $NODEID); an EDS canopen
    cannot read is one line (UserInputError)."""
    path = device_file(name)
    try:
        return canopen.import_od(str(path), node_id)
    except Exception as error:                     # canopen raises what its parsers raise
        raise UserInputError(f"{path}: not an EDS canopen can read ({error})") from None


def identity_of(name: str) -> Identity:
    """The identity a device of this EDS reports (module docstring)."""
    od = object_dictionary(name)
    info = od.device_information
    try:
        device_type = int(od[DEVICE_TYPE[0]].default or 0)
    except KeyError:
        raise UserInputError(f"{device_file(name)}: no device type (object 0x1000)") from None
    return Identity(device_type, int(info.vendor_number or 0), int(info.product_number or 0),
                    int(info.revision_number or 0))


def local_node(node_id: int, name: str, identity: Identity | None = None) -> canopen.LocalNode:
    """A device of this EDS as a node that answers SDO (canopen's LocalNode: the emulator's
    devices); 0x1000 and 0x1018 from `identity` (default: the EDS's own). Like a stock device
    it refuses, with CiA 301's abort code, a value beyond an object's EDS limits and a PDO
    mapping it cannot carry."""
    identity = identity or identity_of(name)
    od = object_dictionary(name, node_id)
    node = canopen.LocalNode(node_id, od)
    node.set_data(*DEVICE_TYPE, identity.device_type.to_bytes(4, "little"))
    for (index, sub), value in ((VENDOR_ID, identity.vendor_id), (PRODUCT_CODE, identity.product_code),
                                (REVISION, identity.revision)):
        node.set_data(index, sub, value.to_bytes(4, "little"))

    def refuse_what_it_cannot_take(index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes):
        if od.data_type not in INTEGER_TYPES:
            return
        value = int(od.decode_raw(data))
        code = range_abort(od, value) or mapping_write_abort(node.object_dictionary, written_values(node), index,
                                                             subindex, value, name)
        if code:
            raise canopen.SdoAbortedError(code)

    node.add_write_callback(refuse_what_it_cannot_take)
    # canopen's own heartbeat producer on a write of 0x1017 (a thread of its own): the node's
    # owner sends its heartbeats, on its clock (the emulator, plant_emulator/canopen_nodes.py)
    if node.nmt.on_write in node._write_callbacks:
        node._write_callbacks.remove(node.nmt.on_write)
    return node


def range_abort(variable: canopen.objectdictionary.ODVariable, value: int) -> int:
    """The SDO abort for `value` beyond the object's EDS LowLimit/HighLimit (0: within)."""
    if variable.min is not None and value < variable.min:
        return SDO_ABORT_TOO_LOW
    if variable.max is not None and value > variable.max:
        return SDO_ABORT_TOO_HIGH
    return 0


def written_values(node: canopen.LocalNode) -> dict[tuple[int, int], int]:
    """The integer objects written to a local node (by SDO or `set_data`), (index, sub) -> value:
    with its EDS, the node's configuration (`protocol.pdo.pdo_maps`' `written`)."""
    out = {}
    for index, subs in node.data_store.items():
        for sub, data in subs.items():
            variable = node.object_dictionary.get_variable(index, sub)
            if variable is not None and variable.data_type in INTEGER_TYPES:
                out[(index, sub)] = int(variable.decode_raw(data))
    return out


def check_files(names, where: str, error: type[UserInputError]) -> None:
    """A configuration's EDS files, each readable with a device type: else one line (`error`)."""
    for name in names:
        try:
            identity_of(name)
        except UserInputError as problem:
            raise error(f"{where}: {problem}") from None
