"""The hexapod's reference clock slowed online is the clock a log's analysis replays, cycle by
cycle: slowed by valves at their limit (a spool limit the move needs more than), and by flow
running short (a power unit weaker than the controller's model, compared until the supply's
fault it still ends in)."""

import numpy as np
import pytest

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.time_scaling import RATE_ONE, rule_of
from hil.logdata import Event, LogData, Series
from hil.reference_rebuild import rebuild
from protocol.enums import Ack, AckKind, State, WaypointFlag
from tests.support.loops import bus_loop, send_waypoint


def _events(cycle, seq, pose, segment, accel, flags):
    x, y, z = pose
    return [Event(cycle, 0.0, "HOST_WAYPOINT_POS", {"TAG": seq & 15, "X": x, "Y": y, "Z": z}),
            Event(cycle, 0.0, "HOST_WAYPOINT_ROT", {"TAG": seq & 15, "ROLL": 0.0, "PITCH": 0.0, "YAW": 0.0}),
            Event(cycle, 0.0, "HOST_WAYPOINT_TIME", {"TAG": seq & 15, "SEQ": seq, "SEGMENT_TIME": segment,
                                                     "ACCEL_TIME": accel, "FLAGS": flags}),
            Event(cycle, 0.0, "CTRL_ACK", {"KIND": AckKind.WAYPOINT, "SEQ": seq, "RESULT": int(Ack.ACCEPTED),
                                           "QUEUE_FREE": 0})]


def _series(name, signal, values, cycles):
    return Series(name, np.asarray(cycles), np.zeros(len(cycles)), np.asarray(values, float)[:, None], {signal: 0})


@pytest.mark.parametrize("overrides, emulator", [
    ({"limits": {"spool_max_pct": 6.0}}, None),
    (None, {"power_unit": {"pump_flow_l_min": 2.0, "accumulator_gas_cm3": 300.0}}),
], ids=["spool-limit", "short-supply"])
def test_a_slowed_clock_is_the_one_the_log_replays(overrides, emulator):
    loop, ctl, bus = bus_loop("hexapod", "computed-torque", overrides=overrides, emulator=emulator)
    period = loop.period_s
    home = tuple(default_geometry().home_position_m)
    up = (home[0] + 0.03, home[1], home[2] + 0.04)
    flags = WaypointFlag.LAST | WaypointFlag.START
    plan = {10: (0, up, 0.35, 0.1), 11: (1, home, 0.35, 0.1)}
    events, yr, spool, supply, rates = [], [], [], [], []
    for cycle in range(700):
        if cycle in plan:
            seq, pose, segment, accel = plan[cycle]
            assert send_waypoint(ctl, seq, *pose, segment=segment, accel=accel, flags=flags) is Ack.ACCEPTED
            events += _events(cycle, seq, pose, segment, accel, flags)
        loop.cycle()
        yr.append(ctl.status.reference_m.copy())
        spool.append(ctl.spool_sent.copy())
        supply.append(np.where(ctl.meas.pressure_fresh, ctl.meas.ps_pa, np.nan))
        rates.append(ctl.status.time_rate)
        if ctl.status.state is State.FAULT:
            break
    assert min(rates) < 0.75, "the clock was never slowed"
    n = len(yr) - (ctl.status.state is State.FAULT)
    spool, supply = np.array(spool), np.array(supply)
    series = {f"VALVE_CMD_{leg + 1}": _series(f"VALVE_CMD_{leg + 1}", "SPOOL_SETPOINT", spool[:, leg], range(n))
              for leg in range(6)}
    for leg in range(6):
        fresh = np.flatnonzero(np.isfinite(supply[:, leg]))
        series[f"LEG_PRESSURE_{leg + 1}"] = _series(f"LEG_PRESSURE_{leg + 1}", "PS", supply[fresh, leg], fresh)
    log = LogData("synthetic", n, np.zeros(n), series, events, 0, {}, {}, 0)
    ref = rebuild(log, "hexapod", period, initial_position=yr[9], rule=rule_of(ctl.cfg, period))
    assert [m.seqs for m in ref.motions][0] == [0]
    assert all(m.times is not None for m in ref.motions)
    first = ref.motions[0]
    assert first.times[-1] / period < first.end_cycle - first.start + 1    # its clock fell behind the cycles
    np.testing.assert_array_equal(ref.yr[10:n], np.array(yr[10:n]))


def test_without_a_trigger_the_clock_is_the_cycles_since_the_start():
    from firmware_py.config import load_config
    from firmware_py.motion_control.time_scaling import Clock
    clock = Clock(rule_of(load_config(), 0.002), 6)
    clock.start(scaled=True)
    for _ in range(700):
        clock.tick(np.full(6, 0.5))
    assert clock.rate == RATE_ONE and clock.cycles() == 700.0
