"""The platform's tracking error (rig_model.HexapodModel.pose_error_exceeds): the legs'
errors mapped to the platform's pose by the Jacobian at the measured pose, judged in mm and
degrees. With the legs near vertical a sideways error is several times the legs' own, so
the per-leg limit alone lets the platform stray."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.rig_model import HexapodModel
from hil.in_process import InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Fault, State


def _legs_for(model: HexapodModel, pose_error) -> np.ndarray:
    """The legs' errors a platform pose error makes at the measured pose (first order)."""
    return model.platform.jacobian @ np.asarray(pose_error, dtype=float)


def test_a_sideways_error_the_legs_barely_see_is_judged_on_the_platform():
    cfg = load_config()
    model = HexapodModel(cfg, 0.002)
    sideways = _legs_for(model, [0.03, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert np.max(np.abs(sideways)) < 0.4 * cfg.limits.tracking_error_max_m       # every leg well inside its limit
    assert model.pose_error_exceeds(sideways)
    assert abs(model.pose_error[0] - 0.03) < 1e-9                                 # the platform's, recovered
    assert not model.pose_error_exceeds(_legs_for(model, [0.02, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert model.pose_error_exceeds(_legs_for(model, [0.0, 0.0, 0.0, 0.0, 0.0, math.radians(6.0)]))
    assert not model.pose_error_exceeds(_legs_for(model, [0.0, 0.0, 0.0, math.radians(4.0), 0.0, 0.0]))


def test_the_yaw_is_judged_by_the_imus_while_it_is_valid():
    """1 deg of yaw is about one encoder count of the legs': with a valid IMU the yaw's error
    is the fused yaw's (the legs' offset taken out at its first sample), else the legs'."""
    cfg = load_config()
    model = HexapodModel(cfg, 0.002)
    rate, still = np.zeros(3), np.zeros(6)
    model.yaw.update(0.0, np.zeros(3), True, rate, True)          # the first sample: on the legs
    turned = np.array([0.0, 0.0, math.radians(6.0)])
    assert model.yaw.update(0.0, turned, True, rate, True)        # the IMU sees 6 deg the legs do not
    assert model.pose_error_exceeds(still)
    assert model.pose_error[5] == pytest.approx(-math.radians(6.0), abs=math.radians(0.05))
    legs_turned = _legs_for(model, [0.0, 0.0, 0.0, 0.0, 0.0, math.radians(6.0)])
    level = HexapodModel(cfg, 0.002)                              # the IMU at the reference's yaw
    for _ in range(2):
        level.yaw.update(0.0, np.zeros(3), True, rate, True)
    assert not level.pose_error_exceeds(legs_turned)
    for _ in range(round(cfg.computed_torque.imu_max_age_s / 0.002) + 1):     # the IMU silent: the legs'
        model.yaw.update(0.0, turned, False, rate, False)
    assert not model.yaw.valid and not model.pose_error_exceeds(still)
    assert model.pose_error_exceeds(legs_turned)


def test_the_controller_faults_when_the_platform_strays_sideways():
    loop = InProcessLoop(load_config(), load_emulator_config(), "computed-torque")
    loop.activate()
    assert loop.status.state is State.READY
    ctl = loop.ctl
    rig = ctl.rig
    # the reference moved 30 mm sideways at once: each leg a few mm off, the platform 30 mm
    ctl.reference.hold(ctl.reference.yr + _legs_for(rig, [0.0, 0.03, 0.0, 0.0, 0.0, 0.0]))
    loop.cycles(1)
    assert loop.status.state is State.FAULT and loop.status.fault is Fault.TRACKING_ERROR
    assert np.max(np.abs(ctl.joint.error_m)) < load_config().limits.tracking_error_max_m


def test_the_yaw_is_judged_on_the_imus_sample_not_on_the_held_rate():
    """Between IMU samples (every 32 ms) the estimate carries on with the sample's rate: past a
    turn it runs beyond the platform. The fault is judged on the sample: 4 deg turning back at
    60 deg/s stays 4 deg for the check while the estimate runs past 5."""
    cfg = load_config()
    model = HexapodModel(cfg, 0.002)
    still = np.zeros(6)
    model.yaw.update(0.0, np.zeros(3), True, np.zeros(3), True)            # the first sample: on the legs
    turning = np.array([0.0, 0.0, math.radians(60.0)])
    model.yaw.update(0.0, np.array([0.0, 0.0, math.radians(4.0)]), True, turning, True)
    for _ in range(15):                                                     # 30 ms without a sample
        model.yaw.update(0.0, np.zeros(3), False, turning, False)
    assert math.degrees(model.yaw.yaw_rad) > 5.5                            # the estimate, carried on
    assert not model.pose_error_exceeds(still)
    assert model.pose_error[5] == pytest.approx(-math.radians(4.0), abs=math.radians(0.3))   # the legs blend in
