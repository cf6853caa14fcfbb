"""Configure stock CANopen devices before starting them: each node's layout settings (heartbeat
producer, the valve's device and control mode, hold setpoint, RPDO timeout), then its PDOs as
its EDS maps them with the layout's SYNC start values (`protocol/devices/canopen-layout.toml`),
written by SDO in CiA 301's order (the PDO disabled, its mapping's count 0, the entries, the count, its
transmission type and SYNC start, the PDO enabled again), then every object read back.

The first write a node refuses (an SDO abort: an object it lacks, a mapping it cannot carry),
a node silent for the SDO timeout, or a value that reads back otherwise ends the
configuration: one line naming the node, the object and the values (ConfigurationError).
`client_of(node)` gives the SDO client (canopen's `SdoClient` interface: `download`,
`upload`), on the loop's bus (`identify._LoopSdoClient`) or any canopen network.
"""

from __future__ import annotations

from dataclasses import dataclass

from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from protocol.canopen_layout import Device
from protocol.devices import object_dictionary
from protocol.pdo import COB_ID, COB_ID_INVALID, PARAMETER_BASES, RPDO, SYNC_START, TPDO, TRANSMISSION_TYPE, pdo_maps


class ConfigurationError(RuntimeError):
    """A node refused, did not answer, or reads back other than what was written."""


@dataclass(frozen=True)
class Write:
    index: int
    subindex: int
    value: int


def node_writes(device: Device) -> list[Write]:
    """The SDO writes that configure `device`: its layout settings, then its PDOs in CiA 301's
    order."""
    od = object_dictionary(device.eds, device.node)
    writes = [Write(index, sub, value) for index, sub, value in device.settings]
    for kind in (RPDO, TPDO):
        for pdo in pdo_maps(od, kind, device.name):
            comm, mapping = (base + pdo.number - 1 for base in PARAMETER_BASES[kind])
            entries = [obj.index << 16 | obj.subindex << 8 | obj.bits for obj in pdo.objects]
            writes += [Write(comm, COB_ID, pdo.cob_id | COB_ID_INVALID), Write(mapping, 0, 0)]
            writes += [Write(mapping, k, entry) for k, entry in enumerate(entries, start=1)]
            writes += [Write(mapping, 0, len(entries)), Write(comm, TRANSMISSION_TYPE, pdo.transmission_type)]
            if od.get_variable(comm, SYNC_START) is not None:
                start = device.sync_start if device.sync_start and pdo.sync_period > 1 else pdo.sync_start
                writes.append(Write(comm, SYNC_START, start))
            writes.append(Write(comm, COB_ID, pdo.cob_id))
    return writes


def _name(device: Device) -> str:
    return f"node {device.node} ({device.name})"


def configure_node(client, device: Device) -> dict[tuple[int, int], int]:
    """`device` configured through `client` and read back; the values it holds, or
    ConfigurationError naming the node and the object."""
    od = object_dictionary(device.eds, device.node)
    final = {}
    for write in node_writes(device):
        variable = od.get_variable(write.index, write.subindex)
        where = f"{_name(device)}: 0x{write.index:04X}:{write.subindex} ({variable.name})"
        try:
            client.download(write.index, write.subindex, variable.encode_raw(write.value))
        except SdoAbortedError as error:
            raise ConfigurationError(f"{where} = 0x{write.value:X} refused: {error}") from None
        except SdoCommunicationError:
            raise ConfigurationError(f"{where}: no SDO answer writing 0x{write.value:X}") from None
        final[(write.index, write.subindex)] = write.value
    for (index, sub), value in final.items():
        variable = od.get_variable(index, sub)
        where = f"{_name(device)}: 0x{index:04X}:{sub} ({variable.name})"
        try:
            read = int(variable.decode_raw(client.upload(index, sub)))
        except SdoAbortedError as error:
            raise ConfigurationError(f"{where}: reading it back was refused: {error}") from None
        except SdoCommunicationError:
            raise ConfigurationError(f"{where}: no SDO answer reading it back") from None
        if read != value:
            raise ConfigurationError(f"{where} reads back 0x{read:X}, written 0x{value:X}: not started")
    return final


def configure(client_of, devices: list[Device]) -> None:
    """Every device configured and read back, in order; the first that fails names itself."""
    for device in devices:
        configure_node(client_of(device.node), device)
