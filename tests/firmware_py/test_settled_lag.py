"""A lag still growing when a chain ends (supervision/capacity.py `settled_lag`): the legs hold
the chain's last pose, and only the spare force that pose leaves them stops the lag. Without
it the check accepted a 200 mm sideways move with 6 kg at 20 bar whose deceleration left two
legs overshooting at a pose they hold at 89 % of their pull: they could not pull back, and
MOTION_PLAUSIBILITY latched 0.1 s after the move's end."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.supervision.capacity import Loads, leg_capacity, shortfall_lag
from hil.experiments import MOVEMENT_OVERRIDES
from hil.in_process import PERIOD_S, InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Ack, State, WaypointFlag

NO_PLATFORM = np.zeros((0, 6, 1))


def _braking_leg(held_share: float) -> Loads:
    """One leg holding `held_share` of its push at rest, asked twice its push over the last
    24 ms of 200 ms (a deceleration it cannot give in time)."""
    push = float(leg_capacity(load_config()).limits(np.zeros(1))[0][0])
    n = 100
    static = np.full((n, 1), held_share * push)
    dynamic = np.zeros((n, 1))
    dynamic[88:] = 2.0 * push
    return Loads(PERIOD_S, static, dynamic, np.zeros((n, 1)), np.full((n, 1), 200.0), NO_PLATFORM)


def test_a_lag_growing_at_the_end_is_stopped_by_the_spare_of_the_pose_held():
    capacity = leg_capacity(load_config())
    lags = {}
    for held in (0.0, 0.5, 0.85):
        worst, _, _, left = shortfall_lag(capacity, _braking_leg(held), 1.0, 0.9)
        assert left[0, 0] > 0.0                               # still falling behind at the last sample
        spare = (0.9 - held) * float(capacity.limits(np.zeros(1))[0][0])
        assert worst == pytest.approx(left[1, 0] + left[0, 0] ** 2 * 200.0 / (2.0 * spare))
        lags[held] = worst
    assert lags[0.0] < lags[0.5] < lags[0.85]
    assert math.isinf(shortfall_lag(capacity, _braking_leg(0.9), 1.0, 0.9)[0])   # no spare: it never stops


@pytest.mark.slow                       # in process, a few seconds of emulated rig
def test_a_move_ending_near_the_legs_limit_is_refused_and_runs_at_the_timing_named():
    overrides = {section: dict(values) for section, values in MOVEMENT_OVERRIDES.items()}
    overrides |= {"hexapod": {"payload_kg": 6.0}, "hydraulic_model": {"supply_pressure_bar": 20.0}}
    emulator = load_emulator_config(overrides={"actuator": {"supply_pressure_bar": 20.0}})
    loop = InProcessLoop(load_config(overrides=overrides), emulator, "computed-torque", 6.0, 1)
    loop.activate()
    loop.cycles(round(1.0 / PERIOD_S))
    target, alone = (0.2, 0.0, 0.631), int(WaypointFlag.START | WaypointFlag.LAST)
    segment_s, accel_s = 2.385, 0.116                  # the circle's approach at 2.32 x, which latched
    assert loop.send_waypoint(target, segment_s, accel_s, alone) is Ack.BEYOND_CAPACITY
    factor = loop.time_scale
    assert 1.0 < factor < 4.0
    segment_s, accel_s = math.ceil(segment_s * factor * 1e3) / 1e3, math.ceil(accel_s * factor * 1e3) / 1e3
    assert loop.send_waypoint(target, segment_s, accel_s, alone) is Ack.ACCEPTED
    status, largest = loop.status, 0.0
    for _ in range(round((segment_s + 1.0) / PERIOD_S)):
        loop.cycle()
        position, _ = loop.rig.platform_pose()
        largest = max(largest, float(np.max(np.abs(position - status.reference_pose[:3]))))
    assert status.state is State.READY
    assert largest < 0.005
