"""Valves at their limit (computed_torque.reallocate_into): the free legs' forces are chosen
again so that the platform's wrench comes nearest the wanted one in the weighted norm, the
limited legs giving what their load cells read. numpy's least squares is the oracle; in
process, a short move near the workspace's floor that saturated three valves unevenly and
swung the yaw past its 5 deg bound completes."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.computed_torque import PIN, ComputedTorque, reallocate_into
from hil.experiments import MOVEMENT_OVERRIDES
from hil.in_process import PERIOD_S, InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Ack, State, WaypointFlag


def _scratch():
    return np.zeros(6), np.zeros((6, 6)), np.zeros(6), np.zeros((6, 6)), np.zeros(6)


def test_nothing_limited_leaves_the_forces():
    law = ComputedTorque(load_config(), default_geometry(), 0.002)
    out = np.full(6, 7.0)
    assert not reallocate_into(law.dynamics.jacobian, np.ones(6), np.zeros(6), np.full(6, 0.5), 1.0,
                               law.allocation_weights, PIN, *_scratch()[:4], out)
    assert np.all(out == 7.0)
    five = np.array([1.0, 1.0, -1.0, 1.0, 1.0, 0.2])          # one leg free: nothing to choose
    assert not reallocate_into(law.dynamics.jacobian, np.ones(6), np.zeros(6), five, 1.0,
                               law.allocation_weights, PIN, *_scratch()[:4], out)


def test_the_free_legs_take_the_weighted_least_squares_wrench():
    law = ComputedTorque(load_config(), default_geometry(), 0.002)
    jacobian, weights = law.dynamics.jacobian.copy(), law.allocation_weights
    rng = np.random.default_rng(4)
    for limited in ([0], [0, 3], [1, 2, 5]):
        wanted = rng.normal(0.0, 200.0, 6)
        measured = wanted + rng.normal(0.0, 80.0, 6)
        spool = np.full(6, 0.3)
        spool[limited] = [-1.0, 1.0, -1.0][:len(limited)]
        out = np.zeros(6)
        assert reallocate_into(jacobian, wanted, measured, spool, 1.0, weights, PIN, *_scratch()[:4], out)
        free = [i for i in range(6) if i not in limited]
        d = np.sqrt(weights)
        residual = jacobian.T @ wanted - jacobian[limited].T @ measured[limited]
        oracle, *_ = np.linalg.lstsq(d[:, None] * jacobian[free].T, d * residual, rcond=None)
        assert np.allclose(out[limited], measured[limited], rtol=1e-4, atol=1e-3)
        assert np.allclose(out[free], oracle, rtol=1e-3, atol=1e-2)
        if len(free) >= 3:                                    # the rotations kept where the free legs can
            rotations = (jacobian.T @ out)[3:]
            assert np.allclose(rotations, (jacobian.T @ wanted)[3:], atol=0.05 * np.abs(jacobian.T @ wanted).max())


def _near_the_floor() -> tuple[InProcessLoop, float]:
    """4.5 kg at 25 bar, 45 mm sideways and 24 mm down to z = 560 mm at the check's own edge
    (about 0.16 s): (the loop with the move accepted, its duration)."""
    overrides = {section: dict(values) for section, values in MOVEMENT_OVERRIDES.items()}
    overrides |= {"hexapod": {"payload_kg": 4.5}}
    loop = InProcessLoop(load_config(overrides=overrides), load_emulator_config(), "computed-torque", 4.5, 1)
    loop.activate()
    alone = int(WaypointFlag.START | WaypointFlag.LAST)
    loop.waypoint((-0.0275, 0.0522, 0.5837), 2.0, 0.5, alone)
    loop.cycles(round(3.0 / PERIOD_S))
    target, segment_s, accel_s = (0.0021, 0.0753, 0.56), 0.1264, 0.05
    assert loop.send_waypoint(target, segment_s, accel_s, alone) is Ack.BEYOND_CAPACITY
    scale = loop.time_scale * 1.001
    assert loop.send_waypoint(target, segment_s * scale, accel_s * scale, alone) is Ack.ACCEPTED
    return loop, segment_s * scale


@pytest.mark.slow                       # in process, a few seconds of emulated rig
def test_an_uneven_saturation_near_the_floor_does_not_swing_the_yaw():
    """Three valves saturate there, two one way and one the other."""
    loop, duration = _near_the_floor()
    status, yaw = loop.status, 0.0
    for _ in range(round((duration + 0.6) / PERIOD_S)):
        loop.cycle()
        w, x, y, z = loop.rig.platform_pose()[1]
        yaw = max(yaw, abs(math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))))
    assert status.state is State.READY
    assert yaw < 3.0


@pytest.mark.slow                       # in process, a few seconds of emulated rig
def test_a_saturated_cycle_makes_no_numpy_buffer():
    """The law's update while valves saturate and the allocation runs: no NumPy buffer made
    (the counting hook around each update alone, the emulator left out)."""
    import firmware_py.motion_control.computed_torque as computed_torque
    from hil.tools.alloc_count import counting
    loop, duration = _near_the_floor()
    law, kernel, chosen = loop.ctl.rig.computed_torque, computed_torque.reallocate_into, [0]

    def counted_kernel(*args):
        done = kernel(*args)
        chosen[0] += done
        return done
    with counting() as counts:
        update = law.update

        def counted_update(*args):
            counts.on()
            try:
                return update(*args)
            finally:
                counts.off()
        law.update, computed_torque.reallocate_into = counted_update, counted_kernel
        try:
            loop.cycles(round(duration / PERIOD_S))
        finally:
            computed_torque.reallocate_into = kernel
        assert chosen[0] >= 5                                 # the allocation ran, cycle after cycle
        assert counts.numpy_buffers == 0
