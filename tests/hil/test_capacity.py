"""`hydrapod design capacity` and the planner (hil/design/capacity.py): the thesis's movements
against the legs' capacity, and the fastest timing the controller's own check accepts."""

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.rig_model import HexapodModel
from firmware_py.supervision.waypoints import WaypointQueue
from hil.design.capacity import EDGE_MARGIN, declared, plan, utilisation
from hil.design.time_optimal import time_optimal
from hil.experiments import MOTIONS, MOVEMENT_OVERRIDES, movement_waypoints
from hil.scenarios import SCENARIOS
from program.errors import UserInputError
from protocol.enums import Ack, State
from tests.support.cli import hydrapod


def _first_refusal(cfg, motion) -> tuple[Ack, WaypointQueue]:
    """`motion`'s waypoints committed to a controller's queue configured with `cfg`: the first
    refusal (ACCEPTED when none) and the queue (its `time_scale_needed`)."""
    rig = HexapodModel(cfg, 0.002)
    queue = WaypointQueue(replace(cfg.waypoints, queue=255), rig.check)
    for seq, w in enumerate(movement_waypoints(motion)):
        queue.stage_position(seq, *w.position_m)
        queue.stage_rotation(seq, 0.0, 0.0, 0.0)
        result = queue.commit(seq, seq, w.segment_time_s, w.accel_time_s, w.flags, State.READY, rig.home_strokes,
                              0.0)
        if result is not Ack.ACCEPTED:
            return result, queue
    return Ack.ACCEPTED, queue


def _accepted(cfg, motion) -> bool:
    """Every waypoint of `motion` accepted by a controller's queue configured with `cfg`."""
    return _first_refusal(cfg, motion)[0] is Ack.ACCEPTED


# near the check's edge acceptance is not monotonic in the time scale (the circle with 0 kg at
# 40 bar: 0.585 and 0.60 accepted, 0.59-0.595 refused); the plan is accepted at the timing sent
@pytest.mark.parametrize("name, payload_kg, supply_bar", [("diagonal", 0.0, 25.0), ("diagonal", 3.0, 25.0),
                                                          ("diagonal", 1.5, 20.0), ("circle", 1.5, 40.0)])
def test_the_plan_keeps_its_margin_from_the_fastest_the_controller_accepts(name, payload_kg, supply_bar):
    cfg = declared(load_config(overrides=MOVEMENT_OVERRIDES), payload_kg, supply_bar)
    motion = MOTIONS[name](default_geometry())
    found = plan(cfg, motion)
    assert math.isfinite(found.time_scale) and found.reason == ""
    assert _accepted(cfg, motion.scaled(found.time_scale))
    assert not _accepted(cfg, motion.scaled(found.time_scale / EDGE_MARGIN * 0.97))   # 3 % beyond its edge


def test_a_payload_needs_more_time_a_higher_supply_less():
    cfg = load_config(overrides=MOVEMENT_OVERRIDES)
    rows = {(m, p): utilisation(cfg, "circle", m, p, optimal=False) for m in (0.0, 3.0) for p in (25.0, 40.0)}
    assert rows[3.0, 25.0].planned_scale > rows[0.0, 25.0].planned_scale
    assert rows[3.0, 40.0].planned_scale < rows[3.0, 25.0].planned_scale
    assert rows[3.0, 25.0].utilisation > rows[0.0, 25.0].utilisation > rows[0.0, 40.0].utilisation


def test_a_static_load_beyond_the_legs_fits_no_time_scale_and_auto_says_why():
    cfg = declared(load_config(overrides=MOVEMENT_OVERRIDES), 6.0, 20.0)
    found = plan(cfg, MOTIONS["circle"](default_geometry()))
    assert math.isnan(found.time_scale) and "BEYOND_CAPACITY" in found.reason
    with pytest.raises(UserInputError, match="--time-scale auto: no time scale .* fits pm-circle"):
        SCENARIOS["pm-circle"].planned_time_scale({**MOVEMENT_OVERRIDES, "hexapod": {"payload_kg": 6.0},
                                                   "hydraulic_model": {"supply_pressure_bar": 20.0}})


def test_fit_runs_at_the_thesiss_timing_where_it_fits_else_at_the_plan():
    sections = {**MOVEMENT_OVERRIDES, "hydraulic_model": {"supply_pressure_bar": 40.0}}
    faster, _ = SCENARIOS["pm-circle"].planned_time_scale(sections)
    thesis, how = SCENARIOS["pm-circle"].planned_time_scale(sections, thesis_where_it_fits=True)
    assert faster < 1.0 == thesis and "the thesis's timing" in how
    heavier = {**MOVEMENT_OVERRIDES, "hexapod": {"payload_kg": 3.0}}
    assert (SCENARIOS["pm-circle"].planned_time_scale(heavier, thesis_where_it_fits=True)[0]
            == SCENARIOS["pm-circle"].planned_time_scale(heavier)[0] > 1.0)
    # the diagonal with 0 kg at 25 bar: its edge just below the thesis's timing, the plan 2 % above it
    diagonal = SCENARIOS["pm-diagonal"]
    assert diagonal.planned_time_scale(MOVEMENT_OVERRIDES)[0] > 1.0
    assert diagonal.planned_time_scale(MOVEMENT_OVERRIDES, thesis_where_it_fits=True)[0] == 1.0


def test_the_scenario_plans_with_the_sections_it_runs_the_controller_with():
    scale, how = SCENARIOS["pm-diagonal"].planned_time_scale({**MOVEMENT_OVERRIDES, "hexapod": {"payload_kg": 3.0}})
    assert 1.0 < scale < 3.0 and "payload 3 kg" in how
    empty, _ = SCENARIOS["pm-diagonal"].planned_time_scale(MOVEMENT_OVERRIDES)
    assert empty < scale


def test_no_timing_the_check_accepts_without_a_lag_beats_the_time_optimal_one():
    """TOPP-RA (toppra) as the oracle: with (almost) no lag allowed and no accumulator, the
    controller's check is a strict force and flow bound, and no SLS timing it accepts can be
    faster than the time-optimal parameterisation of the same path within the same bounds."""
    strict = load_config(overrides={**MOVEMENT_OVERRIDES, "waypoints": {**MOVEMENT_OVERRIDES["waypoints"],
                                                                        "lag_max_mm": 0.01},
                                    "power_unit": {"accumulator_gas_cm3": 0.0}})
    circle = MOTIONS["circle"](default_geometry())
    (optimal_s, sls_s), = time_optimal(strict, circle)
    planned = plan(strict, circle).time_scale
    assert 0.5 * sls_s < optimal_s <= 1.02 * planned * sls_s
    lenient = utilisation(load_config(overrides=MOVEMENT_OVERRIDES), "circle", optimal=False)
    assert lenient.planned_scale < planned                 # the lag allowed buys time


def test_a_force_beyond_what_the_leg_gives_at_its_speed_is_over_one():
    from firmware_py.supervision.capacity import leg_capacity
    capacity = leg_capacity(load_config())
    at_rest = float(np.interp(0.0, capacity.velocities_m_s, capacity.push_n))
    ratios = capacity.utilisation(np.array([0.5 * at_rest, at_rest, 10.0, -10.0]), np.array([0.0, 0.0, 3.0, 0.0]))
    assert ratios[0] == pytest.approx(0.5) and ratios[1] == pytest.approx(1.0)
    assert math.isinf(ratios[2]) and 0.0 < ratios[3] < 0.1


def test_the_commands_print_the_table_and_refuse_bad_arguments():
    out = hydrapod("design", "capacity", "--movements", "circle", "--payload-kg", "0", "--supply-bar", "40")
    assert out.returncode == 0 and "circle" in out.stdout and "planned scale" in out.stdout
    for argv in (("design", "capacity", "--supply-bar", "0"),
                 ("hil", "run", "pm-circle", "--time-scale", "fast"),
                 ("hil", "run", "sha-step", "--time-scale", "auto")):
        bad = hydrapod(*argv)
        assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, (argv, bad.stderr)


def test_a_refusal_names_a_slower_timing_even_at_the_checks_edge():
    """Within ~1 % of its edge the check is not monotonic in the time scale (quantised times,
    sampled lags); a refusal still names a factor above 1, so a host that sends the movement
    again at it makes progress (a refusal that named 0.99 would be sent again as slow and refused again)."""
    cfg = declared(load_config(overrides=MOVEMENT_OVERRIDES), 0.0, 40.0)
    circle = MOTIONS["circle"](default_geometry())
    refusals = 0
    for scale in np.arange(0.56, 0.605, 0.005):
        result, queue = _first_refusal(cfg, circle.scaled(float(scale)))
        if result is Ack.BEYOND_CAPACITY:
            refusals += 1
            assert queue.time_scale_needed > 1.0, (scale, queue.time_scale_needed)
    assert refusals >= 5
