"""The PDO codecs (protocol/pdo.py) against canopen's own PdoMap as the oracle: any mapping of
integer objects within 64 bits packs and unpacks as canopen does; the shipped devices' PDOs
are read from their EDS; a mapping the device cannot carry is one line; nothing allocates."""

import gc
import math
import tracemalloc

import canopen
import numpy as np
import pytest
from canopen.objectdictionary import ODVariable
from canopen.objectdictionary import datatypes as dt
from canopen.pdo.base import PdoMap as CanopenPdoMap
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.canopen_layout import load_layout
from protocol.codec import EncodeStatus
from protocol.devices import object_dictionary
from protocol.pdo import (
    RPDO,
    SDO_ABORT_NOT_MAPPABLE,
    SDO_ABORT_PDO_LENGTH,
    SDO_ABORT_TOO_HIGH,
    TPDO,
    PdoCodec,
    PdoError,
    mapping_write_abort,
    pdo_maps,
)

INTEGER_TYPES = {dt.INTEGER8: 8, dt.INTEGER16: 16, dt.INTEGER24: 24, dt.INTEGER32: 32, dt.INTEGER64: 64,
                 dt.UNSIGNED8: 8, dt.UNSIGNED16: 16, dt.UNSIGNED24: 24, dt.UNSIGNED32: 32}
FIRST_INDEX = 0x2000


def _layouts():
    """Lists of object types whose bits fit one PDO."""
    def fits(types):
        return sum(INTEGER_TYPES[t] for t in types) <= 64
    return st.lists(st.sampled_from(sorted(INTEGER_TYPES)), min_size=1, max_size=8).filter(fits)


def _dictionary(types) -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()
    for j, data_type in enumerate(types):
        variable = ODVariable(f"object {j}", FIRST_INDEX + j, 0)
        variable.data_type, variable.pdo_mappable = data_type, True
        od.add_object(variable)
    return od


def _written(types, cob_id=0x181) -> dict:
    """TPDO1 as a master writes it: COB-ID, every SYNC, the objects in order."""
    entries = {(0x1A00, j + 1): (FIRST_INDEX + j) << 16 | INTEGER_TYPES[t] for j, t in enumerate(types)}
    return {(0x1800, 1): cob_id, (0x1800, 2): 1, (0x1A00, 0): len(types)} | entries


def _oracle(od, types) -> CanopenPdoMap:
    pdo = CanopenPdoMap(canopen.LocalNode(1, od).tpdo, None, None)
    for j in range(len(types)):
        pdo.add_variable(FIRST_INDEX + j)
    return pdo


def _value(data_type):
    bits = INTEGER_TYPES[data_type]
    if data_type in dt.SIGNED_TYPES:
        return st.integers(-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
    return st.integers(0, (1 << bits) - 1)


@st.composite
def _mapping_and_values(draw):
    types = draw(_layouts())
    return types, [draw(_value(t)) for t in types]


@settings(max_examples=200, deadline=None)
@given(_mapping_and_values())
def test_any_mapping_packs_as_canopen_does(case):
    types, values = case
    od = _dictionary(types)
    (pdo,) = pdo_maps(od, TPDO, "DEVICE", _written(types))
    codec = PdoCodec(pdo)
    oracle = _oracle(od, types)
    for j, value in enumerate(values):
        oracle[FIRST_INDEX + j].raw = value
    buf = codec.new_buffer()
    assert codec.encode_into(values, buf) is EncodeStatus.OK
    assert bytes(buf) == bytes(oracle.data) and codec.dlc == len(oracle.data)


@settings(max_examples=200, deadline=None)
@given(_layouts(), st.binary(min_size=8, max_size=8))
def test_any_frame_unpacks_as_canopen_does(types, frame):
    od = _dictionary(types)
    (pdo,) = pdo_maps(od, RPDO, "DEVICE", {(0x1400, 1): 0x201, (0x1400, 2): 1, (0x1600, 0): len(types)}
                      | {(0x1600, k[1]): v for k, v in _written(types).items() if k[0] == 0x1A00 and k[1]})
    codec = PdoCodec(pdo)
    oracle = _oracle(od, types)
    data = frame[:codec.dlc]
    oracle.data = bytearray(data)
    out = np.zeros(len(types))
    assert codec.decode_into(data, out)
    assert out.tolist() == [float(oracle[FIRST_INDEX + j].raw) for j in range(len(types))]


def test_the_shipped_devices_pdos_are_their_eds_s():
    pdos = {}
    for device in load_layout(6):
        od = object_dictionary(device.eds, device.node)
        for kind in (RPDO, TPDO):
            pdos |= {pdo.name: pdo for pdo in pdo_maps(od, kind, device.name)}
    valve = pdos["LEG2_VALVE_RPDO1"]
    assert valve.cob_id == 0x202 and valve.entries() == ((0x6040, 0), (0x6300, 1)) and valve.dlc == 4
    status = pdos["LEG2_VALVE_TPDO1"]
    assert status.entries() == ((0x6041, 0), (0x6301, 1)) and status.sync_period == 1
    assert pdos["LEG1_ENCODER_TPDO1"].entries() == ((0x6004, 0),) and pdos["LEG1_ENCODER_TPDO1"].cob_id == 0x180 + 33
    pressures = pdos["LEG1_LEG_SENSORS_TPDO2"]
    assert pressures.entries() == ((0x7130, 2), (0x7130, 3), (0x7130, 4)) and pressures.sync_period == 16
    assert not any(name.startswith("IMU_RPDO") for name in pdos)


def test_a_mapping_written_by_the_master_replaces_the_eds_s():
    od = object_dictionary("canopen-valve.eds", 4)
    (pdo,) = pdo_maps(od, TPDO, "LEG4_VALVE", {(0x1800, 1): 0x3A4, (0x1800, 2): 2, (0x1A00, 0): 1,
                                                (0x1A00, 1): 0x63010110})
    assert pdo.cob_id == 0x3A4 and pdo.sync_period == 2 and pdo.entries() == ((0x6301, 1),)
    assert pdo_maps(od, TPDO, "LEG4_VALVE", {(0x1800, 1): 0x80000184}) == []       # bit 31: no such PDO


@pytest.mark.parametrize("written, says", [
    ({(0x1A00, 1): 0x20000010}, "LEG1_VALVE TPDO1: entry 0x20000010: the device has no object 0x2000:0"),
    ({(0x1A00, 1): 0x10170010}, "object 0x1017:0 (Producer heartbeat time) may not be mapped"),
    ({(0x1A00, 1): 0x60410020}, "object 0x6041:0 (Status word) is 16 bits, the entry says 32"),
    ({(0x1A00, 0): 3}, "LEG1_VALVE TPDO1: mapping 0x1A00 has 3 entries, no sub-index 3"),
    ({(0x1A00, 0): 5, (0x1A00, 3): 0x60410010, (0x1A00, 4): 0x63010110, (0x1A00, 5): 0x60410010},
     "LEG1_VALVE TPDO1: maps 80 bits, a PDO carries 64"),
])
def test_a_mapping_the_device_cannot_carry_is_one_line(written, says):
    with pytest.raises(PdoError, match=None) as error:
        pdo_maps(object_dictionary("canopen-valve.eds", 1), TPDO, "LEG1_VALVE", written)
    assert says in str(error.value) and "\n" not in str(error.value)


def test_the_count_that_enables_a_mapping_is_refused_as_a_device_refuses_it():
    types = [dt.INTEGER32, dt.INTEGER16, dt.UNSIGNED16, dt.UNSIGNED8]            # 72 bits
    od, written = _dictionary(types), _written(types)
    assert mapping_write_abort(od, written, 0x1A00, 0, 4) == SDO_ABORT_PDO_LENGTH
    assert mapping_write_abort(od, written, 0x1A00, 0, 3) == 0                   # 64 bits
    assert mapping_write_abort(od, written, 0x1A00, 0, 5) == SDO_ABORT_TOO_HIGH
    assert mapping_write_abort(od, written, 0x1A00, 1, 0x10000008) == 0          # entries: judged by the count
    assert mapping_write_abort(od, written | {(0x1A00, 2): 0x20010020}, 0x1A00, 0, 2) == SDO_ABORT_NOT_MAPPABLE


def test_a_value_beyond_its_type_saturates_and_one_not_finite_sends_nothing():
    (pdo,) = pdo_maps(object_dictionary("canopen-valve.eds", 1), RPDO, "LEG1_VALVE")
    codec = PdoCodec(pdo)
    buf, out = codec.new_buffer(), np.zeros(2)
    assert codec.encode_into([0x000F, 40000], buf) is EncodeStatus.SATURATED
    codec.decode_into(buf, out)
    assert out.tolist() == [15.0, 32767.0]
    before = bytes(buf)
    assert codec.encode_into([0x000F, math.nan], buf) is EncodeStatus.REJECTED and bytes(buf) == before
    assert not codec.decode_into(bytes(3), out) and out.tolist() == [15.0, 32767.0]     # short: not processed
    assert codec.decode_into(bytes(buf) + b"\xff\xff", out) and out.tolist() == [15.0, 32767.0]


def test_a_cycle_of_pdos_allocates_nothing():
    codecs = []
    for device in load_layout(6):
        od = object_dictionary(device.eds, device.node)
        codecs += [PdoCodec(pdo) for kind in (RPDO, TPDO) for pdo in pdo_maps(od, kind, device.name)]
    buffers = [codec.new_buffer() for codec in codecs]
    values = [np.zeros(len(codec.pdo.entries())) for codec in codecs]

    def cycle(k: int) -> None:
        for codec, buf, vector in zip(codecs, buffers, values):
            vector[0] = k % 1000
            codec.encode_into(vector, buf)
            codec.decode_into(buf, vector)

    for k in range(200):
        cycle(k)
    gc.collect()
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        for k in range(200, 5200):
            cycle(k)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert after - before < 4096, f"traced memory grew by {after - before} bytes over 5000 cycles"
