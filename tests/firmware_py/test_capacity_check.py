"""The waypoints' capacity check (supervision/capacity.py, waypoints.py): a segment whose
reference asks more than the legs give is refused BEYOND_CAPACITY with the smallest time
scale that fits, and that scale is tight; a brief peak passes where a sustained shortfall
does not; the blend into a chained segment is judged with it."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.supervision.capacity import LegCapacity, Loads, leg_capacity, shortfall_lag
from protocol.enums import TIME_SCALE_NONE_FITS, Ack, time_scale_from_wire, time_scale_to_wire
from tests.support.queues import commit, waypoint_queue

NO_PLATFORM = np.zeros((0, 6, 1))                        # a leg alone: its own lag
AMPLE_PUMP = {"power_unit": {"pump_flow_l_min": 1000.0}}  # the forces alone decide


def test_a_segment_beyond_capacity_is_refused_with_the_time_scale_that_fits():
    queue, model = waypoint_queue("hexapod")
    target = (0.1, 0.1, 0.76, 0.0, 0.0, 0.0)               # 250 mm from home in 0.2 s
    assert commit(queue, model, 0, target, 0.2, 0.05) is Ack.BEYOND_CAPACITY and not queue.queue
    scale = queue.time_scale_needed
    assert 1.0 < scale < 8.0
    assert commit(queue, model, 0, target, 0.2 * scale * 0.97, 0.05 * scale * 0.97) is Ack.BEYOND_CAPACITY
    assert commit(queue, model, 0, target, 0.2 * scale, 0.05 * scale) is Ack.ACCEPTED
    assert math.isnan(queue.time_scale_needed)


def test_a_payload_or_a_lower_supply_asks_for_more_time():
    target = (0.1, 0.1, 0.76, 0.0, 0.0, 0.0)
    scales = {}
    for name, overrides in (("empty", {}), ("payload", {"hexapod": {"payload_kg": 3.0}}),
                            ("20 bar", {"hydraulic_model": {"supply_pressure_bar": 20.0}})):
        queue, model = waypoint_queue("hexapod", {**AMPLE_PUMP, **overrides})
        assert commit(queue, model, 0, target, 0.2, 0.05) is Ack.BEYOND_CAPACITY
        scales[name] = queue.time_scale_needed
    assert scales["payload"] > 1.2 * scales["empty"] and scales["20 bar"] > 1.1 * scales["empty"]


def test_six_legs_drawing_together_beyond_the_pump_and_accumulator_are_refused():
    """A 150 mm rise in 0.5 s: each leg's force within its share, but the valves draw ~14 l/min
    for 0.4 s, beyond the 10 l/min pump by more than a 0.3 l accumulator gives before the
    supply falls below 90 % of its set. An ample pump or the rig's 2.5 l accumulator: accepted."""
    small = {"power_unit": {"accumulator_gas_cm3": 300.0}}
    accepted = {}
    for name, overrides in (("0.3 l", small), ("ample pump", {"power_unit": {"accumulator_gas_cm3": 300.0,
                                                                            "pump_flow_l_min": 1000.0}}),
                            ("2.5 l", {})):
        queue, model = waypoint_queue("hexapod", overrides)
        x, y, z = model.home_pose
        rise = (x, y, z + 0.15, 0.0, 0.0, 0.0)
        accepted[name] = commit(queue, model, 0, rise, 0.5, 0.05)
        if name == "0.3 l":
            scale = queue.time_scale_needed
    assert accepted == {"0.3 l": Ack.BEYOND_CAPACITY, "ample pump": Ack.ACCEPTED, "2.5 l": Ack.ACCEPTED}
    assert 1.0 < scale < 2.0
    queue, model = waypoint_queue("hexapod", small)
    assert commit(queue, model, 0, rise, 0.5 * scale * 0.97, 0.05 * scale * 0.97) is Ack.BEYOND_CAPACITY
    assert commit(queue, model, 0, rise, 0.5 * scale, 0.05 * scale) is Ack.ACCEPTED


def test_a_load_the_leg_cannot_hold_fits_no_time_scale():
    queue, model = waypoint_queue("testbench")
    assert commit(queue, model, 0, (0.0, 0.0, 0.16, 0.0, 0.0, 0.0), 2.0, 0.4, load_kg=5.0) is Ack.ACCEPTED
    assert commit(queue, model, 1, (0.0, 0.0, 0.18, 0.0, 0.0, 0.0), 2.0, 0.4, load_kg=40.0) is Ack.BEYOND_CAPACITY
    assert math.isinf(queue.time_scale_needed)
    assert time_scale_to_wire(queue.time_scale_needed) == TIME_SCALE_NONE_FITS


def test_a_brief_peak_leaves_a_small_lag_a_sustained_shortfall_a_growing_one():
    capacity = leg_capacity(load_config())
    push_at_rest = float(capacity.limits(np.zeros(1))[0][0])
    n = 500                                                  # 1 s at 2 ms, at rest
    brief = np.zeros((n, 1))
    brief[100:112] = 2.0 * push_at_rest                      # twice the push for 24 ms
    sustained = np.zeros((n, 1))
    sustained[100:] = 1.1 * push_at_rest                     # 10 % beyond it from 0.2 s on
    zero = np.zeros((n, 1))
    inertia = np.full((n, 1), 200.0)
    lag_brief = shortfall_lag(capacity, Loads(0.002, zero, brief, zero, inertia, NO_PLATFORM), 1.0, 1.0)[0]
    lag_sustained = shortfall_lag(capacity, Loads(0.002, sustained, zero, zero, inertia, NO_PLATFORM), 1.0, 1.0)[0]
    assert 0.0 < lag_brief < 1e-3             # pushed behind by F/m for 24 ms, braked as hard: (F/m) t^2
    assert lag_sustained > 10e-3
    # a share kept for control makes the same peak longer and deeper
    assert shortfall_lag(capacity, Loads(0.002, zero, brief, zero, inertia, NO_PLATFORM), 1.0, 0.85)[0] > lag_brief


def test_the_blend_into_a_chained_segment_is_judged_with_it():
    """Two segments each fine alone: reversing without stopping asks the blend for twice
    the velocity change and is refused; ending the first at rest is accepted."""
    queue, model = waypoint_queue("testbench")
    up, down = (0.0, 0.0, 0.23, 0.0, 0.0, 0.0), (0.0, 0.0, 0.08, 0.0, 0.0, 0.0)
    home = float(model.home_strokes[0])
    assert home < 0.23
    assert commit(queue, model, 0, up, 0.12, 0.03, flags=0, load_kg=1.0) is Ack.ACCEPTED
    assert commit(queue, model, 1, down, 0.12, 0.03, load_kg=1.0) is Ack.BEYOND_CAPACITY
    queue.clear()
    assert commit(queue, model, 0, up, 0.12, 0.03, load_kg=1.0) is Ack.ACCEPTED
    assert commit(queue, model, 1, down, 0.12, 0.03, load_kg=1.0) is Ack.ACCEPTED


def test_the_time_scale_on_the_wire_rounds_up_and_says_none_and_not_applicable():
    assert time_scale_to_wire(1.2301) == pytest.approx(1.24)
    assert time_scale_to_wire(1.23) == pytest.approx(1.23)
    assert time_scale_to_wire(math.nan) == 0.0 and math.isnan(time_scale_from_wire(0.0))
    assert time_scale_to_wire(1e9) == TIME_SCALE_NONE_FITS and math.isinf(time_scale_from_wire(TIME_SCALE_NONE_FITS))
    assert time_scale_from_wire(time_scale_to_wire(2.5)) == pytest.approx(2.5)


def test_the_capacity_is_computed_once_per_supply():
    cfg = load_config()
    first, again = leg_capacity(cfg), leg_capacity(cfg)
    assert first.push_n is again.push_n
    other = LegCapacity.of(cfg.hydraulics, cfg.friction.vector, 40e5)
    assert np.nanmin(other.push_n - first.push_n) > 0.0
