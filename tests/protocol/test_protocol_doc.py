"""docs/PROTOCOL.md is what the controller does: its command table against the supervisor,
and the E2E rule it states against the library's CRC."""

from __future__ import annotations

from pathlib import Path

import pytest
from e2e.p01 import E2E_P01_DATAID_BOTH, e2e_p01_protect

from firmware_py.supervision.supervisor import Supervisor
from protocol.codec import CODECS
from protocol.enums import Ack, Command, State

DOC = Path(__file__).resolve().parents[2] / "docs" / "PROTOCOL.md"


def command_table() -> dict[tuple[str, str], str]:
    lines = DOC.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| command |"))
    states = [cell.strip() for cell in lines[start].strip("|").split("|")][1:]
    table = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        table.update({(cells[0], state): cell for state, cell in zip(states, cells[1:])})
    return table


def test_the_command_table_is_the_supervisors():
    table = command_table()
    assert {command for command, _ in table} == {c.name for c in Command}
    assert {state for _, state in table} == {s.name for s in State}
    for (command, state), cell in table.items():
        sup = Supervisor()
        sup.state = State[state]
        result = sup.command(Command[command], 1 if command == "SELECT_CONTROLLER" else 0)
        if cell == "ok":
            assert result is Ack.ACCEPTED and sup.state is State[state], (command, state)
        elif cell.startswith("→"):
            assert result is Ack.ACCEPTED and sup.state is State[cell[1:].strip()], (command, state)
        else:
            assert result is Ack[cell] and sup.state is State[state], (command, state)


def crc8_profile1(data: bytes) -> int:
    """CRC-8 SAE J1850 (0x1D), start 0x00, no final XOR: the rule PROTOCOL.md states."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


@pytest.mark.parametrize("name", [n for n in CODECS if CODECS[n].e2e])
def test_the_stated_e2e_rule_is_the_librarys(name):
    codec = CODECS[name]
    assert codec.data_id == codec.frame_id                    # "here: its CAN id"
    buf = bytearray(range(0x40, 0x40 + codec.dlc))
    e2e_p01_protect(buf, codec.data_id, data_id_mode=E2E_P01_DATAID_BOTH, length=codec.dlc, increment_counter=True)
    assert buf[0] == crc8_profile1(bytes([codec.data_id & 0xFF, codec.data_id >> 8]) + bytes(buf[1:]))
