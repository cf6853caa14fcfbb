"""The hexapod's joint-space loops with the emulator's hexapod, in process (no bus): the
testbench's gains diverge on the 190 kg horizontal joint-space inertia; `[hexapod] kp_factor`
and `ki_factor` (defaults 2 and 0.1) hold it (docs/MEASUREMENTS.md "Hexapod gains")."""

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES, JP_KI_SCALE, JP_KP_SCALE, JP_PI_KI, JP_PI_KP, ST_KP
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.rigs import HexapodRig
from protocol.enums import State

PERIOD_S = 0.002
ENCODER_M = 0.125e-3


def hold_after_kick(factors: dict, seconds: float = 4.0, kick_m: float = 0.005):
    """Hold at home with the [hexapod] gain factors given, leg 0's reference moved by `kick_m`;
    returns (final state, peak |xy| mm)."""
    # this loop applies each command in its own cycle, not at the next SYNC: no spool check
    cfg = load_config(overrides={"hexapod": factors, "residuals": {"spool_check": False}})
    rig = HexapodRig(load_emulator_config())
    ctl = Controller(cfg, "hexapod", PERIOD_S, CONTROLLER_NAMES["adaptive"])
    meas, cmd = ctl.new_interfaces()

    def measure():
        meas.position_m[:] = np.round(rig.stroke_m / ENCODER_M) * ENCODER_M
        meas.force_n[:] = rig.rod_force_n
        meas.fresh[:] = True
        meas.valve_state[:] = 3

    measure()
    ctl.update(meas, cmd)
    ctl.activated(True)
    assert ctl.state is State.READY
    ctl.reference.hold_position[0] += kick_m
    peak = 0.0
    for _ in range(int(seconds / PERIOD_S)):
        measure()
        ctl.update(meas, cmd)
        rig.command[:] = cmd.spool
        rig.advance(PERIOD_S)
        peak = max(peak, float(np.hypot(*rig.platform_pose()[0][:2])) * 1e3)
        if ctl.state is State.FAULT:
            break
    return ctl.state, peak


def test_gain_factors_scale_every_controllers_gains_on_the_hexapod_only():
    cfg = load_config(overrides={"hexapod": {"kp_factor": 3.0, "ki_factor": 0.25}})
    hexapod = Controller(cfg, "hexapod", PERIOD_S)
    bench = Controller(cfg, "testbench", PERIOD_S)
    assert hexapod.joint.jp[JP_PI_KP] == pytest.approx(3.0 * cfg.pi.kp_v_m)
    assert hexapod.joint.jp[JP_KP_SCALE] == 3.0
    assert hexapod.joint.jp[JP_PI_KI] == pytest.approx(0.25 * cfg.pi.ki_v_m_s)
    assert hexapod.joint.jp[JP_KI_SCALE] == pytest.approx(0.25 * cfg.adaptive.ki_scale)
    assert bench.joint.jp[JP_PI_KP] == cfg.pi.kp_v_m and bench.joint.jp[JP_KP_SCALE] == 1.0
    assert bench.joint.jp[JP_PI_KI] == cfg.pi.ki_v_m_s and bench.joint.jp[JP_KI_SCALE] == cfg.adaptive.ki_scale


def test_scheduled_kp_is_scaled_by_the_hexapod_kp_factor():
    scaled = {}
    for factor in (1.0, 2.0):
        ctl = Controller(load_config(overrides={"hexapod": {"kp_factor": factor}}), "hexapod", PERIOD_S,
                         CONTROLLER_NAMES["adaptive"])
        n, ref = ctl.n, ctl.reference
        ctl.joint.update(np.full(n, 0.1), np.ones(n, dtype=bool), np.zeros(n), ref.yr, ref.ar, ctl.gravity_axial,
                         ctl.tau_n, True)
        scaled[factor] = ctl.joint.st[:, ST_KP].copy()
    assert np.all(scaled[1.0] > 0.0) and np.allclose(scaled[2.0], 2.0 * scaled[1.0])


def test_testbench_gains_diverge_on_the_hexapod_and_the_defaults_hold():
    state, peak = hold_after_kick({"kp_factor": 1.0, "ki_factor": 1.0})
    assert state is State.FAULT and peak > 100.0          # the oscillation grew to the error limit
    state, peak = hold_after_kick({})
    assert state is State.READY and peak < 50.0           # the kick's own offset is ~21 mm
