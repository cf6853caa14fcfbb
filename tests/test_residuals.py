"""The actuator residuals (firmware_py/residuals.py) on the emulator's hexapod in process:
quiet on a healthy move (margin >= 1.5), the leg named when its spool sticks (within 25
cycles) or its rod seizes (30 cycles measured: the valve first has to open against the
blocked piston), every leg when the supply is lost."""

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.control import CONTROLLER_NAMES
from firmware_py.controller import Controller
from firmware_py.residuals import ActuatorResiduals, breakaway_force_n
from physics import hydraulics as hy
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.rigs import HexapodRig
from protocol.enums import State

PERIOD_S = 0.002
ENCODER_M = 0.125e-3
FAULT_AT = 400                     # cycles into the move (20 mm/s)
DETECT_WITHIN = 25


def run_move(fault: str | None, cycles: int = 700):
    """Home, then every leg +30 mm at 20 mm/s with the adaptive controller; `fault` injected
    FAULT_AT cycles in. Returns (max |r| / threshold before the fault, per cycle after it:
    legs faulty, worst leg)."""
    cfg = load_config()
    ecfg = load_emulator_config()
    rig = HexapodRig(ecfg)
    ctl = Controller(cfg, "hexapod", PERIOD_S, CONTROLLER_NAMES["adaptive"])
    meas, cmd = ctl.new_interfaces()
    res = ActuatorResiduals(6, ecfg.hp, cfg.friction, ecfg.supply_pressure_pa, PERIOD_S, ctl.geometry.rod.mass_kg,
                            cfg.ct_stiffness_n_m, ENCODER_M, gain=0.1, filter_s=0.01, persistence=3,
                            flow_spread=0.135)
    no_pressure = np.zeros(6, dtype=bool)
    applied = np.zeros(6)

    def cycle():
        meas.position_m[:] = np.round(rig.stroke_m / ENCODER_M) * ENCODER_M
        meas.force_n[:] = rig.rod_force_n
        meas.fresh[:] = True
        meas.valve_state[:] = 3
        ctl.update(meas, cmd)
        rig.command[:] = applied
        applied[:] = cmd.spool
        rig.advance(PERIOD_S)

    cycle()
    ctl.activated(True)
    assert ctl.state is State.READY
    for _ in range(50):
        cycle()
    ref = ctl.reference
    ref.move(ref.yr, ref.yr + 0.03, 0.02, 0.2, ctl.cycles)
    res.start(meas.position_m, meas.force_n, ctl.gravity_axial, no_pressure, meas.pa_pa, meas.pb_pa)
    quiet, after = 0.0, []
    for k in range(cycles):
        if k == FAULT_AT and fault == "seized":
            rig.set_rod_seized(0, True)
        elif k == FAULT_AT and fault == "spool":
            rig.jammed[0] = True
            rig.state[0, hy.S_SPOOL] = 0.2
        elif k == FAULT_AT and fault == "supply":
            rig.set_supply_fraction(0.0)
        spool = applied.copy()                       # what the valves apply at this SYNC
        cycle()
        res.update(spool, meas.position_m, meas.force_n, ctl.gravity_axial, no_pressure, meas.pa_pa, meas.pb_pa)
        if k < FAULT_AT:
            if k > 10:
                quiet = max(quiet, float(res.ratio.max()))
        else:
            after.append((res.legs_faulty, res.worst_leg))
    return quiet, after


def test_threshold_floor_is_the_seals_breakaway_force():
    cfg = load_config()
    assert breakaway_force_n(cfg.friction) == pytest.approx(12.1994 + 10.6468)


def test_quiet_on_a_healthy_move_with_margin():
    quiet, after = run_move(None)
    assert quiet < 1.0 / 1.5
    assert all(n == 0 for n, _ in after)


@pytest.mark.parametrize(("fault", "within"), [("spool", DETECT_WITHIN), ("seized", 40)])
def test_a_leg_fault_names_the_leg(fault, within):
    _, after = run_move(fault)
    first = next(k for k, (n, _) in enumerate(after) if n > 0)
    assert first <= within
    assert after[first] == (1, 0)


def test_a_lost_supply_faults_several_legs():
    _, after = run_move("supply")
    assert max(n for n, _ in after) >= 3
