"""The hexapod's joint-space loops with the emulator's hexapod, in process (no bus): the
testbench's gains diverge on the 190 kg horizontal joint-space inertia; `[hexapod] kp_factor`
and `ki_factor` (defaults 2 and 0.1) hold it (docs/MEASUREMENTS.md "Hexapod gains")."""

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.motion_control.joint_space import (
    ADAPTIVE,
    JP_KI_SCALE,
    JP_KP_SCALE,
    JP_PI_KI,
    JP_PI_KP,
    ST_KP,
    JointController,
)
from firmware_py.rig_model import HexapodModel, TestbenchModel
from hil.in_process import InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import State

PERIOD_S = 0.002


def hold_after_kick(factors: dict, seconds: float = 4.0, push_n: float = 40.0):
    """Hold at home with the [hexapod] gain factors given, the platform pushed sideways
    (`push_n` for 50 ms, EMU_KICK's push); returns (final state, peak |xy| mm)."""
    loop = InProcessLoop(load_config(overrides={"hexapod": factors}), load_emulator_config(), "adaptive")
    loop.activate(100)
    assert loop.status.state is State.READY
    loop.rig.kick(0, push_n, 0.05)
    peak = 0.0
    for _ in range(int(seconds / PERIOD_S)):
        loop.cycle()
        peak = max(peak, float(np.hypot(*loop.rig.platform_pose()[0][:2])) * 1e3)
        if loop.faulted:
            break
    return loop.status.state, peak


def test_gain_factors_scale_every_controllers_gains_on_the_hexapod_only():
    cfg = load_config(overrides={"hexapod": {"kp_factor": 3.0, "ki_factor": 0.25}})
    hexapod, bench = HexapodModel(cfg, PERIOD_S), TestbenchModel(cfg, PERIOD_S)
    assert (hexapod.kp_factor, hexapod.ki_factor) == (3.0, 0.25) and (bench.kp_factor, bench.ki_factor) == (1.0, 1.0)
    joint = JointController(cfg, 6, PERIOD_S, moving_mass_kg=1.0, mass_offset_kg=0.0, kp_factor=3.0, ki_factor=0.25)
    assert joint.jp[JP_PI_KP] == pytest.approx(3.0 * cfg.pi.kp_v_m)
    assert joint.jp[JP_KP_SCALE] == 3.0
    assert joint.jp[JP_PI_KI] == pytest.approx(0.25 * cfg.pi.ki_v_m_s)
    assert joint.jp[JP_KI_SCALE] == pytest.approx(0.25 * cfg.adaptive.ki_scale)


def test_scheduled_kp_is_scaled_by_the_hexapod_kp_factor():
    cfg = load_config()
    scaled = {}
    for factor in (1.0, 2.0):
        joint = JointController(cfg, 6, PERIOD_S, moving_mass_kg=1.0, mass_offset_kg=0.0, kp_factor=factor)
        joint.set_mode(ADAPTIVE)
        n = 6
        joint.update(np.full(n, 0.1), np.ones(n, dtype=bool), np.zeros(n), np.full(n, 0.1), np.zeros(n),
                     np.full(n, 9.81), np.zeros(n), True)
        scaled[factor] = joint.st[:, ST_KP].copy()
    assert np.all(scaled[1.0] > 0.0) and np.allclose(scaled[2.0], 2.0 * scaled[1.0])


def test_testbench_gains_diverge_on_the_hexapod_and_the_defaults_hold():
    """A 20 N push for 50 ms: the bench's gains swing the platform out until its tracking
    bound (25 mm) faults; the defaults bring it back."""
    state, peak = hold_after_kick({"kp_factor": 1.0, "ki_factor": 1.0}, push_n=20.0)
    assert state is State.FAULT and peak < 30.0
    state, peak = hold_after_kick({}, push_n=20.0)
    assert state is State.READY and peak < 20.0           # the push alone moves it ~17 mm
