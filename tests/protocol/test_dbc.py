"""The DBC: loads in stock cantools, has the message set and ids of docs/PROTOCOL.md, and meets the
scaling, protection and schedule rules of the protocol."""

import math
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from protocol.codec import CODECS
from protocol.dbc import dbc_path, load_database, schedules, sync_counter_overflow

DB = load_database()
LEGS = range(1, 7)


def sig(message: str, signal: str):
    return DB.get_message_by_name(message).get_signal_by_name(signal)


def test_loads_in_stock_cantools_strict():
    db = cantools.database.load_file(str(dbc_path()), strict=True)
    assert len(db.messages) == len(DB.messages) > 40


def test_cantools_dump_shows_it():
    cantools_cli = Path(sys.executable).with_name("cantools")
    result = subprocess.run([str(cantools_cli), "dump", str(dbc_path())], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    for name in ("VALVE_CMD_1", "LEG_STATE_6", "HOST_WAYPOINT_POS", "EMU_CTRL", "SPOOL_SETPOINT"):
        assert name in result.stdout


def test_message_set_of_the_design():
    names = {m.name for m in DB.messages}
    required = {"SYNC", "IMU_ATTITUDE", "IMU_RATE", "HOST_CMD", "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT",
                "CTRL_STATUS", "EMU_CTRL"}
    for n in LEGS:
        required |= {f"VALVE_CMD_{n}", f"VALVE_STATUS_{n}", f"LEG_STATE_{n}", f"LEG_PRESSURE_{n}"}
    assert required <= names
    for node in DB.nodes:
        if "NodeId" in node.dbc.attributes:
            node_id = node.dbc.attributes["NodeId"].value
            assert f"EMCY_{node_id}" in names and f"HEARTBEAT_{node_id}" in names, node.name


def test_canopen_style_ids():
    assert DB.get_message_by_name("SYNC").frame_id == 0x080
    assert DB.get_message_by_name("NMT").frame_id == 0x000
    node_ids = {n.name: n.dbc.attributes["NodeId"].value for n in DB.nodes if "NodeId" in n.dbc.attributes}
    for name, node_id in node_ids.items():
        assert DB.get_message_by_name(f"EMCY_{node_id}").frame_id == 0x080 + node_id
        assert DB.get_message_by_name(f"HEARTBEAT_{node_id}").frame_id == 0x700 + node_id
        assert DB.get_message_by_name(f"EMCY_{node_id}").senders == [name]
    for n in LEGS:
        assert DB.get_message_by_name(f"LEG_STATE_{n}").frame_id == 0x180 + n       # TPDO1
        assert DB.get_message_by_name(f"VALVE_STATUS_{n}").frame_id == 0x280 + n    # TPDO2
        assert DB.get_message_by_name(f"LEG_PRESSURE_{n}").frame_id == 0x380 + n    # TPDO3
        assert DB.get_message_by_name(f"VALVE_CMD_{n}").frame_id == 0x200 + n       # RPDO1
    assert all(m.frame_id <= 0x7FF and not m.is_extended_frame for m in DB.messages)


def test_valve_commands_win_arbitration_over_slow_and_host_frames():
    # Lower id = higher priority: a valve command must never wait behind status,
    # pressure, host or heartbeat traffic (only behind one frame already in progress).
    worst_cmd = max(DB.get_message_by_name(f"VALVE_CMD_{n}").frame_id for n in LEGS)
    for name in ["HOST_CMD", "HOST_WAYPOINT_POS", "EMU_CTRL"] + [f"VALVE_STATUS_{n}" for n in LEGS] \
            + [f"LEG_PRESSURE_{n}" for n in LEGS]:
        assert DB.get_message_by_name(name).frame_id > worst_cmd, name


def test_scaling_fits_the_rig():
    pos = sig("LEG_STATE_1", "POSITION")
    assert pos.unit == "mm" and pos.scale <= 0.01 and pos.maximum - pos.minimum >= 320
    assert (pos.maximum - pos.minimum) / pos.scale <= 2 ** pos.length - 1
    assert math.isclose(0.125 / pos.scale, round(0.125 / pos.scale)), "encoder steps must be exact"
    force = sig("LEG_STATE_1", "FORCE")
    assert force.unit == "N" and force.scale <= 0.1 and force.minimum <= -2000 and force.maximum >= 2000
    for p in ("PA", "PB"):
        s = sig("LEG_PRESSURE_1", p)
        assert s.unit == "bar" and s.scale <= 0.01 and s.minimum <= 0 and s.maximum >= 60
    spool = sig("VALVE_CMD_1", "SPOOL_SETPOINT")
    assert spool.is_signed and spool.length == 16 and spool.unit == "%"
    assert spool.scale * 16384 == 100.0
    for m, s in [("IMU_ATTITUDE", a) for a in ("ROLL", "PITCH", "YAW")] + \
                [("HOST_WAYPOINT_ROT", a) for a in ("ROLL", "PITCH", "YAW")]:
        angle = sig(m, s)
        assert angle.unit == "rad" and angle.scale <= 0.001 and angle.maximum >= math.pi - 1e-3, (m, s)


def test_every_leg_frame_has_the_same_layout():
    for base in ("LEG_STATE", "VALVE_CMD", "VALVE_STATUS", "LEG_PRESSURE"):
        ref = [(s.name, s.start, s.length, s.scale, s.is_signed) for s in DB.get_message_by_name(f"{base}_1").signals]
        for n in LEGS:
            assert [(s.name, s.start, s.length, s.scale, s.is_signed)
                    for s in DB.get_message_by_name(f"{base}_{n}").signals] == ref


def test_every_signal_says_its_unit_and_meaning():
    for m in DB.messages:
        assert m.comment, m.name
        for s in m.signals:
            assert s.comment and len(s.comment) > 8, (m.name, s.name)
            if s.unit:
                assert s.comment.startswith(f"[{s.unit}]"), (m.name, s.name)


def test_cyclic_frames_are_e2e_protected_with_distinct_data_ids():
    ids = []
    for s in schedules():
        codec = CODECS[s.name]
        if s.sync_period and s.name != "SYNC":
            assert codec.e2e, s.name
        if codec.e2e:
            crc, counter = DB.get_message_by_name(s.name).signals[:2]
            assert (crc.name, crc.start, crc.length) == ("E2E_CRC", 0, 8)
            assert (counter.name, counter.start, counter.length) == ("E2E_COUNTER", 8, 4)
            ids.append(s.e2e_data_id)
    assert len(ids) == len(set(ids))
    # Everything but the fixed-format CANopen services (NMT, SYNC, EMCY, heartbeat) is protected.
    unprotected = {s.name for s in schedules() if s.e2e_data_id is None}
    assert unprotected == {n for n in unprotected if n in ("NMT", "SYNC") or n.startswith(("EMCY_", "HEARTBEAT_"))}
    assert len(ids) == len(schedules()) - 2 - 2 * 8


def test_only_sync_leg_state_and_valve_cmd_every_cycle():
    every = sorted(s.name for s in schedules() if s.sync_period == 1)
    assert every == sorted(["SYNC"] + [f"LEG_STATE_{n}" for n in LEGS] + [f"VALVE_CMD_{n}" for n in LEGS])
    slow = {s.name for s in schedules() if s.sync_period > 1}
    assert {"CTRL_STATUS", "CTRL_PAYLOAD", "CTRL_CLOCK", "CTRL_LOAD", "IMU_ATTITUDE", "IMU_RATE"} \
        | {f"VALVE_STATUS_{n}" for n in LEGS} | {f"LEG_PRESSURE_{n}" for n in LEGS} == slow


def test_slow_frames_spread_one_per_cycle_and_fit_the_sync_counter():
    overflow = sync_counter_overflow()
    slots = {}
    for s in schedules():
        if s.sync_period > 1:
            assert overflow % s.sync_period == 0, s.name
            assert 0 <= s.sync_phase < s.sync_period, s.name
            slots.setdefault((s.sync_period, s.sync_phase), []).append(s.name)
    crowded = {k: v for k, v in slots.items() if len(v) > 1}
    assert not crowded, f"slow frames sharing a cycle: {crowded}"


@pytest.mark.parametrize("name", ["HOST_CMD", "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT", "HOST_WAYPOINT_TIME",
                                  "HOST_TEST"])
def test_host_frames_are_protected_and_go_to_the_controller(name):
    m = DB.get_message_by_name(name)
    assert CODECS[name].e2e and m.senders == ["HOST"]
    assert all("CONTROLLER" in s.receivers for s in m.signals)


def test_emu_ctrl_is_simulation_only():
    m = DB.get_message_by_name("EMU_CTRL")
    assert m.senders == ["HOST"] and all(s.receivers == ["EMULATOR"] for s in m.signals)
    assert "imulation only" in m.comment
