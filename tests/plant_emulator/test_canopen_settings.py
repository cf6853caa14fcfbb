"""The emulated stock devices keep what a master writes (plant_emulator/canopen_nodes.py): the
heartbeat producer time (0x1017) sets how often a node beats, a valve's RPDO timeout
(0x1400:5) its command timeout from its next start, a reset forgets both; a value beyond the
EDS's limits is refused with CiA 301's abort code. On the emulator's own clock, frame by frame."""

import can
import pytest

from plant_emulator.emulator import NO_COMMAND_TIMEOUT, Emulator
from plant_emulator.params import load_config
from plant_emulator.rigs import make_rig
from protocol.codec import CODECS
from protocol.enums import NmtCommand

SDO_REQUEST, SDO_RESPONSE, HEARTBEAT = 0x600, 0x580, 0x700
ENCODER, VALVE = 33, 1


class _Wire:
    """The emulator's bus: what it sends, kept."""

    def __init__(self):
        self.sent = []

    def send(self, msg, timeout=None):
        self.sent.append(msg)


@pytest.fixture
def rig():
    cfg = load_config()
    wire, clock = _Wire(), [0.0]
    emulator = Emulator(wire, make_rig("testbench", cfg), cfg, clock=lambda: clock[0], pacing="lockstep",
                        devices="canopen")
    emulator.boot()
    return emulator, wire, clock


def _download(emulator, wire, node: int, index: int, sub: int, value: int, size: int) -> bytes:
    """An expedited SDO download (CiA 301); the node's answer."""
    command = 0x23 | (4 - size) << 2
    data = bytes([command]) + index.to_bytes(2, "little") + bytes([sub]) + value.to_bytes(4, "little")
    wire.sent.clear()
    emulator.handle(can.Message(arbitration_id=SDO_REQUEST + node, data=data, is_extended_id=False))
    (answer,) = [m for m in wire.sent if m.arbitration_id == SDO_RESPONSE + node]
    return bytes(answer.data)


def _beats(emulator, wire, clock, node: int, seconds: float) -> int:
    """Heartbeats of `node` over `seconds` of the emulator's clock, polled every millisecond."""
    wire.sent.clear()
    start = clock[0]
    for k in range(1, round(seconds * 1e3) + 1):
        clock[0] = start + k * 1e-3
        emulator.poll(clock[0])
    return sum(m.arbitration_id == HEARTBEAT + node for m in wire.sent)


def _nmt(emulator, command: NmtCommand, node: int) -> None:
    emulator.handle(can.Message(arbitration_id=CODECS["NMT"].frame_id, data=bytes([int(command), node]),
                                is_extended_id=False))


def test_a_node_beats_at_its_written_heartbeat_time_and_a_reset_restores_the_eds_s(rig):
    emulator, wire, clock = rig
    assert 9 <= _beats(emulator, wire, clock, ENCODER, 1.0) <= 10                 # the EDS's 100 ms
    assert _download(emulator, wire, ENCODER, 0x1017, 0, 20, 2)[0] == 0x60        # taken
    assert 48 <= _beats(emulator, wire, clock, ENCODER, 1.0) <= 50
    assert _download(emulator, wire, ENCODER, 0x1017, 0, 0, 2)[0] == 0x60
    assert _beats(emulator, wire, clock, ENCODER, 1.0) == 0                       # 0: it sends none
    assert 9 <= _beats(emulator, wire, clock, VALVE, 1.0) <= 10                   # the others as they were
    _nmt(emulator, NmtCommand.RESET_NODE, ENCODER)
    assert 9 <= _beats(emulator, wire, clock, ENCODER, 1.0) <= 10


def test_a_valves_rpdo_timeout_is_its_command_timeout_from_its_start(rig):
    emulator, wire, _ = rig
    valve = emulator.sim.valves[0]
    assert _download(emulator, wire, VALVE, 0x1400, 5, 10, 2)[0] == 0x60         # 10 ms
    _nmt(emulator, NmtCommand.START, VALVE)
    assert emulator.sim.valves[0].command_timeout_syncs == 5                    # SYNC periods of 2 ms
    _nmt(emulator, NmtCommand.RESET_NODE, VALVE)                                # back to the EDS's 0: none
    _nmt(emulator, NmtCommand.START, VALVE)
    assert emulator.sim.valves[0] is not valve and emulator.sim.valves[0].command_timeout_syncs == NO_COMMAND_TIMEOUT


def test_a_repeated_start_keeps_the_compiled_pdos_until_something_is_written(rig):
    # a master repeats its START until it hears OPERATIONAL; compiling the PDOs again each
    # time starved the heartbeats of an emulator in a software-emulated VM
    emulator, wire, _ = rig
    _nmt(emulator, NmtCommand.START, VALVE)
    started = emulator.canopen.tpdos[VALVE]
    _nmt(emulator, NmtCommand.START, VALVE)
    assert emulator.canopen.tpdos[VALVE] is started
    assert _download(emulator, wire, VALVE, 0x1400, 5, 10, 2)[0] == 0x60
    _nmt(emulator, NmtCommand.START, VALVE)
    assert emulator.canopen.tpdos[VALVE] is not started and emulator.sim.valves[0].command_timeout_syncs == 5


@pytest.mark.parametrize("index, sub, value, size, abort", [
    (0x6042, 0, 2, 1, 0x06090031),          # device mode: 1 only (setpoint by bus)
    (0x6043, 0, 0, 1, 0x06090032),          # control mode: 1 only (spool position)
    (0x6314, 1, 100, 2, 0x06090031),        # hold setpoint: null only
])
def test_a_value_beyond_the_eds_s_limits_is_refused(rig, index, sub, value, size, abort):
    emulator, wire, _ = rig
    answer = _download(emulator, wire, VALVE, index, sub, value, size)
    assert answer[0] == 0x80 and int.from_bytes(answer[4:8], "little") == abort
    assert _download(emulator, wire, VALVE, index, sub, 1 if index != 0x6314 else 0, size)[0] == 0x60
