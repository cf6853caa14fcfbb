"""The supply's floor and the legs' share are two margins (supervision/capacity.py): how far
the oil a segment draws beyond the pump may lower the supply (`[waypoints] supply_share_pct`,
also where the online time scaling acts), and how much of a leg's force the reference may
ask (`capacity_share_pct`). Each moves only its own judgement."""

import pytest

from firmware_py.config import load_config
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.time_scaling import rule_of
from firmware_py.supervision.capacity import LegCapacity, PlatformLoads, judge, leg_capacity
from hil.design.capacity import PERIOD_S, stroke_trajectory
from hil.design.simulate import point_configs, thesis_motions


def _diagonal_loads(cfg):
    geometry = default_geometry()
    trajectory = stroke_trajectory(thesis_motions()["diagonal"], geometry)
    return PlatformLoads(geometry, cfg.kinematics.dk_tolerance_m, angle_weight=cfg.waypoints.angle_weight_m_rad
                         ).loads(trajectory, 0.0, trajectory.duration_s, PERIOD_S)


def test_the_supply_floor_moves_the_oil_reserve_alone():
    cfg, _ = point_configs(0.0, 40.0)
    loads = _diagonal_loads(cfg)
    share, lag_max = cfg.waypoints.capacity_share, cfg.waypoints.lag_max_m
    packaged = judge(leg_capacity(cfg), loads, 1.0, share, lag_max)
    lower = load_config(overrides={"waypoints": {"supply_share_pct": 80.0},
                                   "hydraulic_model": {"supply_pressure_bar": 40.0}})
    deeper = judge(leg_capacity(lower), loads, 1.0, share, lag_max)
    assert deeper.reserve_m3 > 1.5 * packaged.reserve_m3            # 80 % of 40 bar gives twice 90 %'s oil
    assert deeper.deficit_m3 == packaged.deficit_m3 and deeper.lag_m == packaged.lag_m
    assert rule_of(lower, PERIOD_S).supply_low_pa == pytest.approx(0.8 * 40e5)


def test_a_power_unit_needs_its_floor():
    cfg = load_config()
    with pytest.raises(ValueError, match="share of its set pressure"):
        LegCapacity.of(cfg.hydraulics, cfg.friction.vector, 25e5, cfg.power, cfg.valve_map.at_supply(25e5))
