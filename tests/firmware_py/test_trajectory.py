"""SLS profiles (eq. 11.1-11.4): boundary conditions, continuity, multi-point, named motions."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import DirectKinematics
from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX, check_poses
from firmware_py.motion_control.trajectory import sls_coefficients, through_points
from hil.experiments import MOTIONS

GEOMETRY = default_geometry()
finite = st.floats(-0.3, 0.3)


def _continuity(traj, dt=1e-5):
    t = np.arange(-0.01, traj.duration_s + 0.05, dt)
    pos, vel, acc = traj.sample(t)
    return t, pos, vel, acc


@settings(max_examples=60)
@given(y0=st.lists(finite, min_size=3, max_size=3), yf=st.lists(finite, min_size=3, max_size=3),
       v0=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3), ta=st.floats(0.02, 0.2),
       ratio=st.floats(2.0, 10.0))
def test_point_to_point_meets_its_boundary_conditions(y0, yf, v0, ta, ratio):
    tm = ta * ratio
    traj = through_points(np.array([y0, yf]), ta, tm, start_velocity=v0)
    pos, vel, acc = traj.sample([0.0, tm, tm + 1.0])
    assert np.allclose(pos[0], y0, atol=1e-12) and np.allclose(vel[0], v0, atol=1e-12)
    assert np.allclose(pos[1], yf, atol=1e-12) and np.allclose(vel[1], 0.0, atol=1e-12)
    assert np.allclose(acc[0], 0.0, atol=1e-9) and np.allclose(acc[1], 0.0, atol=1e-9)
    assert np.allclose(pos[2], yf, atol=1e-12) and np.allclose(vel[2], 0.0)


def test_multi_point_passes_every_point_with_continuous_velocity_and_acceleration():
    rng = np.random.default_rng(4)
    points = rng.uniform(0.55, 0.8, size=(7, 6))
    traj = through_points(points, 0.05, 0.25)
    ends = np.arange(1, 7) * 0.25
    pos, vel, _ = traj.sample(ends)
    assert np.allclose(pos, points[1:], atol=1e-12)
    assert np.allclose(vel[-1], 0.0) and not np.allclose(vel[2], 0.0)     # no stop between points
    t, pos, vel, acc = _continuity(traj)
    dt = t[1] - t[0]
    jerk_bound = np.abs(acc).max() * np.pi / 0.05                       # |d acc/dt| <= a_max w
    assert np.abs(np.diff(vel, axis=0)).max() <= np.abs(acc).max() * dt * 1.001
    assert np.abs(np.diff(acc, axis=0)).max() <= jerk_bound * dt * 1.001
    assert np.allclose(np.gradient(pos, dt, axis=0)[5:-5], vel[5:-5], atol=1e-6)


def test_invalid_timing_is_refused():
    with pytest.raises(ValueError, match="tm >= 2 ta"):
        sls_coefficients([0.0], [0.0], [1.0], 0.1, 0.15, True)
    with pytest.raises(ValueError, match="at least two points"):
        through_points(np.zeros((1, 6)), 0.05, 0.25)


@pytest.mark.parametrize("name", sorted(MOTIONS))
def test_named_motions_stay_in_the_usable_workspace(name):
    motion = MOTIONS[name](GEOMETRY)
    traj = motion.joint_trajectory(GEOMETRY)
    t = np.arange(0.0, traj.duration_s, 0.005)
    lengths, vel, _ = traj.sample(t)
    assert np.all(lengths >= GEOMETRY.leg_min_m) and np.all(lengths <= GEOMETRY.leg_max_m)
    # headroom for tracking errors: a leg 1 mm from an end stop while moving is a POSITION_LIMIT
    # fault, and the joint errors on the hexapod reach 10-20 mm (docs/MEASUREMENTS.md "Hexapod gains")
    assert lengths.min() - GEOMETRY.leg_min_m >= 0.025 and GEOMETRY.leg_max_m - lengths.max() >= 0.025
    solver = DirectKinematics(GEOMETRY)
    poses = np.empty((len(t), 7))
    for k, row in enumerate(lengths):
        solver.solve(row)
        assert solver.converged
        poses[k] = solver.pose
    report = check_poses(GEOMETRY, poses[:, :3], poses[:, 3:])
    assert report.reachable.all()
    assert report.condition_index.min() >= MIN_CONDITION_INDEX
    # the platform reaches every waypoint with the orientation fixed
    starts = np.cumsum([0.0] + [motion.tm_s] * (len(motion.waypoints()) - 1))
    reached, _, _ = traj.sample(starts)
    from firmware_py.mechanics.kinematics import ik_batch
    expected, _ = ik_batch(GEOMETRY, motion.waypoints(), np.tile([1.0, 0, 0, 0], (len(starts), 1)))
    assert np.allclose(reached, expected, atol=1e-12)
