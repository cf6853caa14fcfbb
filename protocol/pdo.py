"""A device's PDOs (CiA 301), compiled once from its object dictionary for the hot path.

What a PDO carries is data, never code: its communication parameter (RPDO 0x1400 + k, TPDO
0x1800 + k: the COB-ID, the transmission type, the SYNC start value) and its mapping (0x1600
+ k, 0x1A00 + k: up to 64 bits of entries 0xIIIISSLL, the object's index, sub-index and
length in bits), as the EDS's defaults or as a master wrote them by SDO (`written`: what a
DCF or a read-back holds). `pdo_maps` reads them and refuses a mapping the device cannot
carry (an object it lacks or may not map, a length that is not the object's, more than 64
bits) with one line naming the device, the PDO and the entry (PdoError).

`PdoCodec` packs the mapped objects' raw values (the integers of the object dictionary, in
mapping order) into a frame and unpacks them, in integer arithmetic on preallocated buffers,
as `protocol.codec` does for the DBC's frames; canopen's own `PdoMap` is its oracle in the
tests. Scaling to SI is the device profile's, not this module's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import canopen
from canopen.objectdictionary import datatypes

from protocol.codec import STANDARD_ID_MASK, EncodeStatus

RPDO, TPDO = "RPDO", "TPDO"
PARAMETER_BASES = {RPDO: (0x1400, 0x1600), TPDO: (0x1800, 0x1A00)}    # communication, mapping
PDOS_PER_KIND = 512
COB_ID, TRANSMISSION_TYPE, SYNC_START = 1, 2, 6       # the communication parameter's sub-indices
COB_ID_INVALID = 1 << 31             # the PDO does not exist (CiA 301, 0x14xx/0x18xx:1 bit 31)
PDO_MAX_BITS = 64
SYNC_CYCLIC_MAX = 240                # transmission types 1..240: every n-th SYNC
DUMMY_INDEX_MAX = 0x001F             # entries at the data types' indices are padding (dummy mapping)


# CiA 301 SDO abort codes with which a device refuses a write
SDO_ABORT_NOT_MAPPABLE = 0x06040041       # object cannot be mapped to the PDO
SDO_ABORT_PDO_LENGTH = 0x06040042         # the objects to be mapped would exceed the PDO's length
SDO_ABORT_TOO_HIGH = 0x06090031           # value of parameter written too high (more entries than it has)
SDO_ABORT_TOO_LOW = 0x06090032            # value of parameter written too low


class PdoError(ValueError):
    """A PDO's parameters the device cannot carry: one line naming it and the entry;
    `abort_code` the SDO abort with which the device refuses them."""

    def __init__(self, message: str, abort_code: int = SDO_ABORT_NOT_MAPPABLE):
        super().__init__(message)
        self.abort_code = abort_code


@dataclass(frozen=True)
class MappedObject:
    index: int
    subindex: int
    bits: int
    offset: int                      # the first bit in the frame
    signed: bool
    dummy: bool = False              # padding: sent as zeros, never read

    @property
    def raw_min(self) -> int:
        return -(1 << (self.bits - 1)) if self.signed else 0

    @property
    def raw_max(self) -> int:
        return (1 << (self.bits - 1)) - 1 if self.signed else (1 << self.bits) - 1


@dataclass(frozen=True)
class PdoMap:
    device: str
    kind: str                        # RPDO or TPDO
    number: int                      # 1-based, as CiA 301 counts them
    cob_id: int
    transmission_type: int
    sync_start: int                  # 0: none (sent from the first SYNC)
    objects: tuple[MappedObject, ...]

    @property
    def name(self) -> str:
        return f"{self.device}_{self.kind}{self.number}"

    @property
    def bits(self) -> int:
        return sum(obj.bits for obj in self.objects)

    @property
    def dlc(self) -> int:
        return math.ceil(self.bits / 8)

    @property
    def sync_period(self) -> int:
        """Every n-th SYNC (0: not SYNC-cyclic: acyclic, or event-driven)."""
        return self.transmission_type if 1 <= self.transmission_type <= SYNC_CYCLIC_MAX else 0

    def due_at(self, counter: int) -> bool:
        """Whether a SYNC-cyclic PDO is sent at SYNC `counter` (1-based): every
        `sync_period`-th, from its SYNC start value (CiA 301 0x18xx:6)."""
        period = self.sync_period
        if period <= 1:
            return period == 1
        return (counter - (self.sync_start or 1)) % period == 0

    def entries(self) -> tuple[tuple[int, int], ...]:
        """The mapped objects' (index, sub-index), padding left out, in mapping order."""
        return tuple((obj.index, obj.subindex) for obj in self.objects if not obj.dummy)


def object_value(od: canopen.ObjectDictionary, written: dict, index: int, subindex: int) -> int | None:
    """An object's value: as written, else its EDS default (None: the device lacks it)."""
    if (index, subindex) in written:
        return int(written[(index, subindex)])
    variable = od.get_variable(index, subindex)
    if variable is None or variable.default is None:
        return None
    return int(variable.default)


def _mapped(od, device: str, where: str, entry: int, offset: int) -> MappedObject:
    index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
    name = f"{device} {where}: entry 0x{entry:08X}"
    if bits == 0:
        raise PdoError(f"{name} maps no bits")
    if index <= DUMMY_INDEX_MAX:
        return MappedObject(index, subindex, bits, offset, False, dummy=True)
    variable = od.get_variable(index, subindex)
    if variable is None:
        raise PdoError(f"{name}: the device has no object 0x{index:04X}:{subindex}")
    if not variable.pdo_mappable:
        raise PdoError(f"{name}: object 0x{index:04X}:{subindex} ({variable.name}) may not be mapped")
    if variable.data_type not in datatypes.INTEGER_TYPES:
        raise PdoError(f"{name}: object 0x{index:04X}:{subindex} ({variable.name}) is not an integer")
    if bits != len(variable):
        raise PdoError(f"{name}: object 0x{index:04X}:{subindex} ({variable.name}) is {len(variable)} bits, "
                       f"the entry says {bits}")
    return MappedObject(index, subindex, bits, offset, variable.data_type in datatypes.SIGNED_TYPES)


def _mapping(od, kind: str, k: int, device: str, written: dict) -> tuple[MappedObject, ...]:
    """PDO k's (0-based) mapped objects, each checked against `od`."""
    map_index = PARAMETER_BASES[kind][1] + k
    where = f"{kind}{k + 1}"
    count = object_value(od, written, map_index, 0)
    if count is None:
        raise PdoError(f"{device} {where}: no mapping object 0x{map_index:04X}")
    objects, offset = [], 0
    for sub in range(1, count + 1):
        entry = object_value(od, written, map_index, sub)
        if entry is None:
            raise PdoError(f"{device} {where}: mapping 0x{map_index:04X} has {count} entries, no sub-index {sub}",
                           SDO_ABORT_TOO_HIGH)
        objects.append(_mapped(od, device, where, entry, offset))
        offset += objects[-1].bits
    if offset > PDO_MAX_BITS:
        raise PdoError(f"{device} {where}: maps {offset} bits, a PDO carries {PDO_MAX_BITS}", SDO_ABORT_PDO_LENGTH)
    return tuple(objects)


def pdo_maps(od: canopen.ObjectDictionary, kind: str, device: str = "device",
             written: dict[tuple[int, int], int] | None = None) -> list[PdoMap]:
    """The device's existing PDOs of `kind` (RPDO or TPDO), each with its mapping checked
    against `od`; `written` (index, sub-index) -> value overrides the EDS's defaults."""
    written = written or {}
    comm_base = PARAMETER_BASES[kind][0]
    out = []
    for k in range(PDOS_PER_KIND):
        cob_id = object_value(od, written, comm_base + k, COB_ID)
        if cob_id is None or cob_id & COB_ID_INVALID:
            continue
        objects = _mapping(od, kind, k, device, written)
        transmission = object_value(od, written, comm_base + k, TRANSMISSION_TYPE)
        sync_start = object_value(od, written, comm_base + k, SYNC_START) or 0
        out.append(PdoMap(device, kind, k + 1, cob_id & STANDARD_ID_MASK, 255 if transmission is None else transmission,
                          sync_start, objects))
    return out


def mapping_write_abort(od: canopen.ObjectDictionary, written: dict[tuple[int, int], int], index: int,
                        subindex: int, value: int, device: str = "device") -> int:
    """The SDO abort code with which a device refuses `value` written to (index, sub-index),
    0 where it takes it: a mapping's entry count (sub-index 0, CiA 301's last step of a
    remapping) enables its entries, checked as `pdo_maps` checks them; `written` the values
    written before."""
    for kind, (_, map_base) in PARAMETER_BASES.items():
        if map_base <= index < map_base + PDOS_PER_KIND and subindex == 0 and value:
            try:
                _mapping(od, kind, index - map_base, device, {**written, (index, 0): value})
            except PdoError as error:
                return error.abort_code
    return 0


class PdoCodec:
    """One PDO's frame: `encode_into(raw_values, buf)`, `decode_into(data, out)`; the values
    are the mapped objects' raw integers in `PdoMap.entries()` order."""

    def __init__(self, pdo: PdoMap):
        self.pdo = pdo
        self.name, self.frame_id, self.dlc = pdo.name, pdo.cob_id, pdo.dlc
        fields = [obj for obj in pdo.objects if not obj.dummy]
        self._enc = tuple((i, obj.offset, (1 << obj.bits) - 1, obj.raw_min, obj.raw_max)
                          for i, obj in enumerate(fields))
        self._dec = tuple((obj.offset, (1 << obj.bits) - 1, (1 << (obj.bits - 1)) if obj.signed else 0)
                          for obj in fields)

    def new_buffer(self) -> bytearray:
        return bytearray(self.dlc)

    def encode_into(self, values, buf: bytearray) -> EncodeStatus:
        """Pack raw `values` into `buf`: a value beyond its object's type is saturated
        (SATURATED), a value not finite sends nothing (REJECTED, `buf` untouched)."""
        word, saturated = 0, False
        for i, offset, mask, raw_min, raw_max in self._enc:
            x = values[i]
            if not math.isfinite(x):
                return EncodeStatus.REJECTED
            raw = int(x)
            if raw < raw_min:
                raw, saturated = raw_min, True
            elif raw > raw_max:
                raw, saturated = raw_max, True
            word |= (raw & mask) << offset
        buf[0:self.dlc] = word.to_bytes(self.dlc, "little")
        return EncodeStatus.SATURATED if saturated else EncodeStatus.OK

    def decode_into(self, data, out) -> bool:
        """Unpack `data` into `out`; False (nothing written) when it is shorter than the
        mapping (CiA 301: such a PDO is not processed)."""
        if len(data) < self.dlc:
            return False
        word = int.from_bytes(data, "little")          # bytes beyond the mapping: above every field
        i = 0
        for offset, mask, sign_bit in self._dec:
            raw = (word >> offset) & mask
            if raw & sign_bit:
                raw -= sign_bit << 1
            out[i] = raw
            i += 1
        return True
