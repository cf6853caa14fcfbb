"""The computed torque's valve map at another supply (`ValveMap.at_supply`,
`hydraulics.supply_similarity`): the map derived at 25 bar, its axes and pressures scaled,
against the emulator's own steady states at 20 and 40 bar."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.computed_torque import ComputedTorque, valve_map_eval
from physics import hydraulics as hy
from physics.constants import BAR
from plant_emulator.params import load_config as load_emulator_config

POINTS = [(force, velocity) for force in (-50.0, 0.0, 50.0, 150.0) for velocity in (-0.2, 0.0, 0.2)]


@pytest.mark.parametrize("supply_bar", [20.0, 40.0])
def test_the_scaled_map_holds_the_emulators_steady_state_at_another_supply(supply_bar):
    valve_map = load_config().valve_map
    forces, velocities, spool, pressure_a, _ = valve_map.at_supply(supply_bar * BAR)
    emulator = load_emulator_config(overrides={"actuator": {"supply_pressure_bar": supply_bar}})
    unscaled_errors, errors = [], []
    for force, velocity in POINTS:
        pa, _, x, ok = hy.steady_state(0.15, force, supply_bar * BAR, emulator.hp, velocity)
        if not ok:                                           # retracting fast against a pull at 20 bar
            continue
        errors.append(abs(valve_map_eval(forces, velocities, spool, force, velocity) - x))
        unscaled_errors.append(abs(valve_map_eval(valve_map.force_n, valve_map.velocity_m_s, spool, force, velocity)
                                   - x))
        pressure = valve_map_eval(forces, velocities, pressure_a, force, velocity)
        assert pressure == pytest.approx(pa, abs=0.2 * supply_bar * BAR)
    assert len(errors) >= len(POINTS) - 1
    assert max(errors) < 0.015                               # 1.5 % of full input
    assert max(unscaled_errors) > 3 * max(errors)            # the 25 bar map as it is would be off


def test_the_controller_takes_the_map_at_its_configured_supply():
    at_40 = load_config(overrides={"hydraulic_model": {"supply_pressure_bar": 40.0}})
    law = ComputedTorque(at_40, default_geometry(), 0.002)
    assert law.forces == pytest.approx(at_40.valve_map.force_n * 1.6)
    assert law.velocities == pytest.approx(at_40.valve_map.velocity_m_s * math.sqrt(1.6))
    assert law.rate_floor == pytest.approx(at_40.computed_torque.force_rate_floor * math.sqrt(1.6))
    at_25 = ComputedTorque(load_config(), default_geometry(), 0.002)
    assert np.array_equal(at_25.forces, load_config().valve_map.force_n)
