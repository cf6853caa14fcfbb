"""The supply checked at rest (firmware_py/supervision/plausibility.py `SupplyAtRest`): while
no move plays each valve's P-port transducer reads the power unit's pressure itself, so a
supply other than the configured one is said as the supply's fault at start, before the
chamber prediction (which assumes the configured supply) can name a leg's seal."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.runtime.loop import ControllerLoop
from firmware_py.supervision.plausibility import SupplyAtRest
from hil.in_process import InProcessLoop
from physics.constants import BAR
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Fault, State, WaypointFlag

NOMINAL_PA, TOLERANCE_PA = 25 * BAR, 2 * BAR


def test_three_legs_off_are_the_supply_one_alone_its_transducer():
    check = SupplyAtRest(6, NOMINAL_PA, TOLERANCE_PA, 3)
    assert math.isnan(check.measured_pa)
    ps = np.full(6, NOMINAL_PA)
    for leg in range(6):                               # the legs' samples come one per cycle
        ps[leg] = 20 * BAR
        off, lone = check.update(ps, np.arange(6) == leg)
        assert off == (leg >= 2) and lone == -1
    assert check.measured_pa == pytest.approx(20 * BAR)
    check = SupplyAtRest(6, NOMINAL_PA, TOLERANCE_PA, 3)
    ps = np.full(6, NOMINAL_PA + 0.5 * TOLERANCE_PA)
    ps[3] = 0.0                                        # leg 4's transducer dead
    assert check.update(ps, np.ones(6, dtype=bool)) == (False, -1)   # one sample: wait for its next
    assert check.update(ps, np.ones(6, dtype=bool)) == (False, 3)
    assert check.peak == pytest.approx(NOMINAL_PA / TOLERANCE_PA)
    check.reset()                                      # a move: its samples are not at rest
    assert math.isnan(check.measured_pa) and check.update(ps, np.zeros(6, dtype=bool)) == (False, -1)


def test_the_test_benchs_one_transducer_is_the_supply():
    check = SupplyAtRest(1, NOMINAL_PA, TOLERANCE_PA, 3)
    assert check.update(np.array([30 * BAR]), np.ones(1, dtype=bool)) == (True, -1)


def _activated(supply_bar: float, rig: str = "hexapod", kind: str = "computed-torque") -> InProcessLoop:
    """The emulated rig on a power unit at `supply_bar`, the controller configured for 25 bar,
    activated as the daemon does; then up to 100 cycles while it holds."""
    emulator = load_emulator_config(overrides={"actuator": {"supply_pressure_bar": supply_bar}})
    loop = InProcessLoop(load_config(), emulator, kind, rig=rig)
    loop.activate(0)
    for _ in range(100):
        loop.cycle()
        if loop.status.state is State.FAULT:
            break
    return loop


@pytest.mark.parametrize(("supply_bar", "rig"), [(20.0, "hexapod"), (30.0, "hexapod"), (20.0, "testbench")])
def test_a_supply_5_bar_off_the_configured_is_the_supplys_fault_at_start(supply_bar, rig):
    loop = _activated(supply_bar, rig)
    status = loop.status
    assert status.fault is Fault.SUPPLY_PRESSURE and status.fault_leg == 0, (status.fault.name, status.fault_leg)
    assert status.cycles <= 40, status.cycles          # every leg's first sample: 16 cycles after READY
    # the relief passes the pump's flow less the legs' leakage at rest: a little below its set
    assert status.supply_measured_pa == pytest.approx(supply_bar * BAR, abs=0.15 * BAR)
    note = ControllerLoop._supply_note(status)
    assert f"measured {status.supply_measured_pa / BAR:.1f} bar" in note and "configured 25.0 bar" in note


def test_the_configured_supply_holds_and_moves_with_margin():
    loop = _activated(25.0)
    assert loop.status.state is State.READY
    x, y, z = loop.ctl.rig.home_pose
    loop.waypoint((x + 0.05, y, z + 0.03), 1.0, 0.2, WaypointFlag.START | WaypointFlag.LAST)
    loop.cycles(800)                                   # the move, then holding again
    assert loop.status.state is State.READY and loop.status.faults == 0
    assert math.isnan(loop.status.supply_measured_pa)  # the accumulator refilling: not at rest yet
    loop.cycles(round(loop.ctl.cfg.supply_refill_s / 0.002) + 20)
    assert loop.status.margins.as_dict()["supply_peak"] < 1.0 / 1.5
    assert loop.status.supply_measured_pa == pytest.approx(25 * BAR, abs=0.1 * BAR)
