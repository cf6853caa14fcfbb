"""The emulator's power unit (physics/power_unit.py in the rigs) against the controller's
model of it (supervision/capacity.py's SupplyBudget): at rest the relief holds the set
pressure; legs drawing together empty the accumulator by what the budget says it gives, and
without one they get the pump's flow and no more."""

import numpy as np
import pytest

from firmware_py.config import load_config as load_controller_config
from physics import hydraulics as hy
from physics import power_unit as pu
from physics.constants import BAR, L_MIN
from plant_emulator.params import load_config
from plant_emulator.rigs import HexapodRig

SHARE = 0.9


def _drawn_m3_s(rig) -> float:
    """What the legs' chambers take (A v extending, alpha A |v| retracting)."""
    v, area = rig._velocity, rig.cfg.area_a_m2
    return float(np.sum(np.where(v > 0.0, area * v, -rig.cfg.alpha * area * v)))


def _supply_drawn_m3_s(rig) -> float:
    """What the valves take from the supply through their P edges (their leakage included)."""
    st, hp = rig.state, rig.cfg.hp
    return sum(hy.supply_flow(st[i, hy.S_SPOOL], st[i, hy.S_PA], st[i, hy.S_PB], rig.supply_pressure_pa, hp,
                              rig.ports_open[i])[0] for i in range(rig.n_legs))


def _opened(overrides: dict | None = None, spool: float = 0.3) -> HexapodRig:
    rig = HexapodRig(load_config(overrides=overrides))
    for _ in range(25):                                   # at rest, ports open, valves at null
        rig.advance(0.002)
    rig.command[:] = spool                                # every leg extending, fully drawn
    return rig


def test_at_rest_the_relief_holds_the_set_pressure():
    rig = HexapodRig(load_config())
    for _ in range(50):
        rig.advance(0.002)
    assert rig.supply_pressure_pa == pytest.approx(25.0 * BAR, abs=0.1 * BAR)


def test_the_accumulator_gives_what_the_controllers_budget_says():
    """Below the relief's cracking pressure, down to 90 % of the set: the oil the valves drew
    beyond the pump against `usable_volume` over the same fall, as the controller has it."""
    small = {"power_unit": {"accumulator_gas_cm3": 300.0}}          # drained before the legs' end stops
    power = load_controller_config(overrides=small).power
    rig = _opened(small)
    pump, crack = rig.cfg.power_unit.pump_flow_m3_s, 25.0 * BAR - rig.cfg.power_unit.relief_override_pa
    given, start = 0.0, None
    for _ in range(2000):
        rig.advance(0.002)
        if start is None and rig.supply_pressure_pa < crack:
            start = rig.supply_pressure_pa
        elif start is not None:
            given += (_supply_drawn_m3_s(rig) - pump) * 0.002
            if rig.supply_pressure_pa <= SHARE * 25.0 * BAR:
                break
    assert start is not None and rig.supply_pressure_pa <= SHARE * 25.0 * BAR
    expected = pu.usable_volume(power, start, rig.supply_pressure_pa)
    assert given == pytest.approx(expected, rel=0.05), (given, expected)


def test_without_an_accumulator_the_legs_get_the_pumps_flow():
    rig = _opened({"power_unit": {"accumulator_gas_cm3": 0.0}})
    for _ in range(100):
        rig.advance(0.002)
    drawn = _drawn_m3_s(rig)
    assert 0.8 * 10.0 * L_MIN <= drawn <= 10.0 * L_MIN, drawn / L_MIN
    assert rig.supply_pressure_pa < 0.5 * 25.0 * BAR
