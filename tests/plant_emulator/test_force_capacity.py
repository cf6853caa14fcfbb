"""A leg's force capacity (physics/hydraulics.py `force_capacity`): the steady state of the
valve fully open at a piston velocity, against the emulator's own chamber integration of the
same leg driven at that velocity, and against the areas' bound at rest."""

import math

import numpy as np
import pytest

from physics import hydraulics as hy
from plant_emulator.params import load_config

SUPPLY_PA = 25e5


def _integrated_force(spool: float, velocity_m_s: float, hp: np.ndarray, seconds: float = 0.5) -> float:
    """The emulator's chamber laws (`chamber_step`, its own step) with the spool held open and
    the piston driven at a constant velocity, from mid-stroke, until the pressures settle."""
    state = np.zeros(hy.S_SIZE)
    state[hy.S_PA], state[hy.S_PB], state[hy.S_SPOOL] = 0.5 * SUPPLY_PA, 0.5 * SUPPLY_PA, spool
    step = 1e-5
    y = 0.15
    for _ in range(int(seconds / step)):
        y += velocity_m_s * step
        hy.chamber_step(state, y, velocity_m_s, SUPPLY_PA, step, hp, 1.0, hp[hy.HP_SEAL_LEAK])
    return float(hy.piston_force(state[hy.S_PA], state[hy.S_PB], hp))


@pytest.mark.parametrize("velocity_m_s", [-0.2, 0.0, 0.1, 0.4])
def test_the_capacity_is_where_the_emulators_chambers_settle_with_the_valve_open(velocity_m_s):
    hp = load_config().hp
    push, pull = hy.force_capacity(velocity_m_s, SUPPLY_PA, hp)
    if velocity_m_s >= 0.0:
        assert push == pytest.approx(_integrated_force(1.0, velocity_m_s, hp), rel=2e-3)
    if velocity_m_s <= 0.0 or not math.isnan(pull):
        assert pull == pytest.approx(_integrated_force(-1.0, velocity_m_s, hp), rel=2e-3)


def test_at_rest_the_capacity_is_the_areas_times_supply_and_tank_less_the_leakage():
    hp = load_config().hp
    area, alpha, tank = hp[hy.HP_AREA_A], hp[hy.HP_ALPHA], hp[hy.HP_TANK]
    push, pull = hy.force_capacity(0.0, SUPPLY_PA, hp)
    assert 0.97 * area * (SUPPLY_PA - alpha * tank) < push <= area * (SUPPLY_PA - alpha * tank)
    assert area * (tank - alpha * SUPPLY_PA) <= pull < 0.97 * area * (tank - alpha * SUPPLY_PA)


def test_faster_leaves_less_force_and_beyond_the_valves_speed_none():
    hp = load_config().hp
    pushes = [hy.force_capacity(v, SUPPLY_PA, hp)[0] for v in (0.0, 0.5, 1.0, 2.0, 3.0)]
    assert all(a > b for a, b in zip(pushes, pushes[1:]))
    table = hy.capacity_table(np.array([-0.5, 0.0, 0.5, 6.0]), SUPPLY_PA, hp)
    assert table[0, 0] == table[1, 0] and table[2, 1] == table[1, 1]    # braking: at least as at rest
    assert math.isnan(table[3, 0])                                       # 6 m/s: the open valve cannot
