"""A log of a run on stock CANopen devices reads as the DBC's messages its PDOs stand for: the
positions, pressures and valve commands the controller had, cycle by cycle; the monitor shows
them the same way."""

import json

import can
import numpy as np

from hil.cli import main
from hil.logdata import read_log
from hil.monitor.view import BusView
from protocol import canopen_profile as cp
from protocol.enums import Ack, WaypointFlag
from tests.support.loops import bus_loop, send_waypoint

CYCLES = 120


def _recorded_run(path):
    """An in-process run on stock devices with every frame on the bus logged; per cycle what
    the controller read and commanded."""
    loop, ctl, bus = bus_loop("testbench", "pi", devices="canopen")
    flags = int(WaypointFlag.START | WaypointFlag.LAST)         # moving: the commands are not all 0
    assert send_waypoint(ctl, 1, 0.0, 0.0, float(ctl.status.hold_m[0]) + 0.01, segment=0.2, accel=0.05,
                         flags=flags) is Ack.ACCEPTED
    writer = can.Logger(str(path))
    clock = bus.clock
    send, deliver = bus.send, bus.deliver

    def log(msg):
        writer.on_message_received(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data),
                                               is_extended_id=False, timestamp=1000.0 + clock()))

    def sending(msg, timeout=None):
        log(msg)
        send(msg, timeout)

    def delivering(msg):
        log(msg)
        deliver(msg)

    bus.send, bus.deliver = sending, delivering
    read, spool, states = [], [], []
    for _ in range(CYCLES):
        loop.cycle()
        read.append(float(loop.meas.position_m[0]))
        spool.append(float(loop.cmd.spool[0]))
        states.append(int(loop.meas.valve_state[0]))
    writer.stop()
    return np.array(read), np.array(spool), states


def test_a_stock_device_log_reads_as_the_dbc_messages(tmp_path):
    path = tmp_path / "run.blf"
    read, spool, states = _recorded_run(path)
    log = read_log(path, "canopen")
    assert log.e2e_errors == 0
    state = log.get("LEG_STATE_1")
    positions = state.per_cycle(log.n_cycles, "POSITION")
    # the last CYCLES cycles of the log are the recorded cycles, in order
    np.testing.assert_allclose(positions[-CYCLES:], read, atol=cp.POSITION_STEP_M / 2)
    commands = log.get("VALVE_CMD_1").per_cycle(log.n_cycles, "SPOOL_SETPOINT")
    np.testing.assert_allclose(commands[-CYCLES:], spool, atol=1.0 / cp.SPOOL_FULL_SCALE)
    assert np.ptp(spool) > 0.01 and np.ptp(read) > 5e-3        # a move was recorded
    assert state.per_cycle(log.n_cycles, "VALVE_STATE")[-CYCLES:].tolist() == states
    pressures = log.get("LEG_PRESSURE_1")
    assert CYCLES // 16 <= len(pressures) and np.all(pressures["PS"] > 20e5)
    assert "LEG1_VALVE_TPDO1" in log.rx_counts


def test_the_monitor_shows_a_stock_device_run_as_the_controller_saw_it(tmp_path, capsys):
    """`hydrapod monitor --devices canopen`: the valve's, encoder's and measuring device's PDOs
    fill the leg's row (position, spool command, valve state, pressures); read as the project's
    own nodes, the same log shows no leg."""
    path = tmp_path / "run.blf"
    read, spool, _ = _recorded_run(path)
    stock, own = BusView(devices="canopen"), BusView()
    with can.LogReader(str(path)) as reader:
        for msg in reader:
            for view in (stock, own):
                view.feed(msg.timestamp, msg.arbitration_id, msg.data, msg.is_extended_id)
    leg = stock.snapshot().legs[0]
    assert abs(leg.position_m - read[-1]) <= cp.POSITION_STEP_M / 2
    assert abs(leg.spool_cmd - spool[-1]) <= 1.0 / cp.SPOOL_FULL_SCALE
    assert leg.valve_state == "ACTIVE" and leg.control_bits == "DHM-"          # R only resets a fault
    assert 1e5 < leg.pa_pa < 3e6 and 1e5 < leg.pb_pa < 3e6
    assert stock.snapshot().rejected == 0
    # the stock sensors' heartbeats (node ids the DBC has not) by device name
    assert stock.heartbeats["LEG1_ENCODER"][0] == stock.heartbeats["LEG1_LEG_SENSORS"][0] == "OPERATIONAL"
    assert {"LEG1_VALVE_TPDO1", "LEG1_ENCODER_TPDO1"} <= set(stock.ok_by_message())
    mine = own.snapshot()
    assert mine.n_legs == 0 and mine.rejected > 0 and mine.unknown > 0     # RPDOs fail the E2E check

    assert main(["monitor", "--replay", str(path), "--devices", "canopen", "--speed", "0", "--snapshot",
                 str(tmp_path / "s.svg"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["legs"] == 1 and summary["e2e_rejected"] == 0
