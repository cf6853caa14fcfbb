"""Kinematics: IK/DK round trip, Jacobians vs finite differences, singularities, workspace."""

import numpy as np
import pytest

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import (
    DirectKinematics,
    constraint_into,
    constraint_jacobian_into,
    ik_batch,
    ik_into,
    jacobian_batch,
    jacobian_into,
)
from firmware_py.mechanics.rotation import (
    axis_angle_to_quat,
    quat_multiply,
    quat_to_matrix,
    quat_to_matrix_into,
    quat_to_rpy,
    rotation_angle_between,
    rpy_to_quat,
)
from firmware_py.mechanics.workspace import (
    MIN_CONDITION_INDEX,
    OUT_CLEARANCE,
    OUT_CONDITION,
    OUT_DET,
    OUT_REACHABLE,
    PoseChecker,
    check_poses,
    segment_distance,
)
from hil.tools.dk_eval import sample_workspace

GEOMETRY = default_geometry()


@pytest.fixture(scope="module")
def poses():
    return sample_workspace(GEOMETRY, 10_000, np.random.default_rng(7))


def test_rotation_helpers_agree():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = np.empty((3, 3))
    for k in range(len(q)):
        quat_to_matrix_into(q[k], out)
        assert np.allclose(out, quat_to_matrix(q[k]), atol=1e-15)
    rpy = quat_to_rpy(q)
    assert rotation_angle_between(rpy_to_quat(rpy[:, 0], rpy[:, 1], rpy[:, 2]), q).max() < 1e-12
    # R(p q) = R(p) R(q), and the small-angle precision of rotation_angle_between
    assert np.allclose(quat_to_matrix(quat_multiply(q[0], q[1])), quat_to_matrix(q[0]) @ quat_to_matrix(q[1]))
    tiny = quat_multiply(q[2], axis_angle_to_quat([0.0, 0.0, 1.0], 3e-10))
    assert rotation_angle_between(tiny, q[2]) == pytest.approx(3e-10, rel=1e-3)


def test_ik_kernel_equals_vectorised(poses):
    positions, quats = poses
    lengths, units = ik_batch(GEOMETRY, positions[:500], quats[:500])
    rot, pw, out_l, out_u = np.empty((3, 3)), np.empty((6, 3)), np.empty(6), np.empty((6, 3))
    for k in range(500):
        ik_into(GEOMETRY.base_anchor_m, GEOMETRY.platform_anchor_m, positions[k], quats[k], rot, pw, out_l, out_u)
        assert np.allclose(out_l, lengths[k], atol=1e-15, rtol=0)
        assert np.allclose(out_u, units[k], atol=1e-15, rtol=0)


def test_ik_dk_round_trip_on_10000_poses(poses):
    """DK from home recovers every usable-workspace pose to 1e-9 m and 1e-9 rad."""
    positions, quats = poses
    lengths, _ = ik_batch(GEOMETRY, positions, quats)
    solver = DirectKinematics(GEOMETRY, tolerance_m=1e-13)
    found = np.empty((len(positions), 7))
    for k in range(len(positions)):
        solver.solve(lengths[k], solver.home)
        assert solver.converged, (k, solver.residual_m)
        found[k] = solver.pose
    position_error = np.linalg.norm(found[:, :3] - positions, axis=1)
    orientation_error = rotation_angle_between(found[:, 3:], quats)
    assert position_error.max() <= 1e-9, position_error.max()
    assert orientation_error.max() <= 1e-9, orientation_error.max()


def test_dk_warm_start_tracks_a_motion_in_few_iterations():
    solver = DirectKinematics(GEOMETRY)
    t = np.arange(0.0, 2.0, 0.002)
    positions = np.column_stack([0.1 * np.sin(2 * t), 0.05 * np.cos(3 * t), 0.65 + 0.05 * np.sin(t)])
    quats = rpy_to_quat(0.2 * np.sin(t), 0.1 * np.sin(2 * t), 0.3 * np.sin(0.5 * t))
    lengths, _ = ik_batch(GEOMETRY, positions, quats)
    iterations = [solver.solve(row) for row in lengths]
    assert all(solver.converged for _ in [0])
    assert np.mean(iterations[1:]) <= 2.5
    assert np.linalg.norm(solver.pose[:3] - positions[-1]) < 1e-9


def test_dk_reports_failure_instead_of_raising():
    solver = DirectKinematics(GEOMETRY, max_iterations=5)
    solver.solve(np.array([0.01, 5.0, 0.01, 5.0, 0.01, 5.0]))    # no pose has these legs
    assert not solver.converged and solver.status[0] <= 5
    solver.solve(np.full(6, np.nan))
    assert not solver.converged


def test_dk_never_keeps_a_diverged_iterate():
    """A failed solve leaves the last converged pose (not the Newton iterate) as the next
    warm start, and a wild start is retried from home."""
    solver = DirectKinematics(GEOMETRY)
    target = np.array([[0.02, -0.01, 0.64]])
    lengths, _ = ik_batch(GEOMETRY, target, rpy_to_quat(0.05, 0.0, 0.1)[None])
    solver.solve(lengths[0])
    assert solver.converged
    good = solver.pose.copy()
    solver.solve(np.array([0.01, 5.0, 0.01, 5.0, 0.01, 5.0]))
    assert not solver.converged
    np.testing.assert_array_equal(solver.pose, good)
    wild = np.array([28.4, -13.2, -5.4, 0.28, 0.38, 0.5, 0.7])      # a run-away reference's iterate
    assert solver.solve(lengths[0], wild, fallback=False) >= 0 and not solver.converged
    solver.solve(lengths[0], wild)
    assert solver.converged
    np.testing.assert_allclose(solver.pose[:3], target[0], atol=1e-9)


def test_jacobian_matches_finite_differences_of_ik(poses):
    positions, quats = poses
    rng = np.random.default_rng(3)
    h = 1e-6
    for k in range(50):
        twist = rng.normal(size=6)
        jac = jacobian_batch(GEOMETRY, positions[k], quats[k])[0]
        rates = []
        for sign in (1, -1):
            rot = axis_angle_to_quat(twist[3:], sign * h * np.linalg.norm(twist[3:]))
            lengths, _ = ik_batch(GEOMETRY, positions[k] + sign * h * twist[:3], quat_multiply(rot, quats[k]))
            rates.append(lengths[0])
        numeric = (rates[0] - rates[1]) / (2 * h)
        assert np.allclose(jac @ twist, numeric, atol=1e-7)
        rot_m, pw, lengths, units, out = np.empty((3, 3)), np.empty((6, 3)), np.empty(6), np.empty((6, 3)), \
            np.empty((6, 6))
        ik_into(GEOMETRY.base_anchor_m, GEOMETRY.platform_anchor_m, positions[k], quats[k], rot_m, pw, lengths, units)
        jacobian_into(units, pw, out)
        assert np.allclose(out, jac, atol=1e-15)


def test_constraint_jacobian_eq_9_12_matches_finite_differences(poses):
    positions, quats = poses
    rot, pw, units, phi, gmat, jac = (np.empty((3, 3)), np.empty((6, 3)), np.empty((6, 3)), np.empty(6),
                                      np.empty((3, 4)), np.empty((6, 7)))
    lengths = np.full(6, 0.6)
    for k in range(30):
        q = np.concatenate([positions[k], quats[k]])
        constraint_into(GEOMETRY.base_anchor_m, GEOMETRY.platform_anchor_m, lengths, q, rot, pw, units, phi)
        constraint_jacobian_into(GEOMETRY.platform_anchor_m, q, rot, units, gmat, jac)
        numeric = np.empty((6, 7))
        for j in range(7):
            out = []
            for sign in (1, -1):
                qq = q.copy()
                qq[j] += sign * 1e-7
                f = np.empty(6)
                constraint_into(GEOMETRY.base_anchor_m, GEOMETRY.platform_anchor_m, lengths, qq, rot, pw, units, f)
                out.append(f)
            numeric[:, j] = (out[0] - out[1]) / 2e-7
        # R(p) is evaluated normalised, so compare on the tangent space of the unit sphere
        tangent = np.eye(4) - np.outer(q[3:], q[3:])
        assert np.allclose(jac[:, :3], numeric[:, :3], atol=1e-7)
        assert np.allclose(jac[:, 3:] @ tangent, numeric[:, 3:] @ tangent, atol=1e-6)


def test_singularity_detected_where_det_jx_changes_sign():
    """Yaw about the vertical crosses Fichter's singular surface at 90 deg at any height."""
    yaw = np.radians(np.linspace(0.0, 120.0, 2401))
    for z in (0.583, 0.65, 0.75):
        report = check_poses(GEOMETRY, np.tile([0.0, 0.0, z], (len(yaw), 1)), rpy_to_quat(0.0, 0.0, yaw))
        sign = np.sign(report.det_jx)
        changes = np.nonzero(sign[1:] != sign[:-1])[0]
        assert len(changes) == 1
        assert np.degrees(yaw[changes[0]]) == pytest.approx(90.0, abs=0.1)
        assert report.condition_index[changes[0]] < 1e-3
        assert report.condition_index[0] > 5 * MIN_CONDITION_INDEX


def test_workspace_limits_each_reject_what_they_should():
    home, ident = GEOMETRY.home_position_m, [1.0, 0.0, 0.0, 0.0]
    ok = check_poses(GEOMETRY, home, ident)
    assert ok.reachable[0]
    too_high = check_poses(GEOMETRY, [0.0, 0.0, 0.9], ident)
    assert not too_high.stroke_ok[0] and too_high.universal_ok[0]
    too_low = check_poses(GEOMETRY, [0.0, 0.0, 0.5], ident)
    assert not too_low.stroke_ok[0]
    tilted = check_poses(GEOMETRY, [0.0, 0.0, 0.7], rpy_to_quat(np.radians(70), 0.0, 0.0))
    assert not tilted.spherical_ok[0]
    twisted = check_poses(GEOMETRY, [0.0, 0.0, 0.7], rpy_to_quat(0.0, 0.0, np.radians(160)))
    assert not twisted.interference_ok[0] and twisted.stroke_ok[0]
    far = check_poses(GEOMETRY, [0.75, 0.0, 0.45], ident)
    assert not far.reachable[0]


def test_the_compiled_pose_check_agrees_with_the_vectorised_one():
    """PoseChecker (a waypoint commit's per-pose kernel) against check_poses (its oracle) over
    poses on both sides of every limit: reach, cones, interference, singular surface."""
    rng = np.random.default_rng(11)
    n = 3000
    positions = GEOMETRY.home_position_m + rng.uniform([-0.5, -0.5, -0.25], [0.5, 0.5, 0.25], (n, 3))
    quats = rpy_to_quat(*rng.uniform(-1.2, 1.2, (3, n)) * np.array([[0.6], [0.6], [1.8]]))
    report = check_poses(GEOMETRY, positions, quats)
    assert 0.1 < report.reachable.mean() < 0.9
    assert (~report.interference_ok & report.stroke_ok).any() and (~report.spherical_ok).any()
    checker = PoseChecker(GEOMETRY)
    for k in range(n):
        out = checker.check(positions[k], quats[k])
        assert bool(out[OUT_REACHABLE]) == report.reachable[k], k
        assert out[OUT_CLEARANCE] == pytest.approx(report.min_clearance_m[k], abs=1e-12)
        assert out[OUT_DET] == pytest.approx(report.det_jx[k], rel=1e-9, abs=1e-12)
        assert out[OUT_CONDITION] == pytest.approx(report.condition_index[k], rel=1e-9, abs=1e-12)
        assert np.allclose(checker.lengths, report.lengths_m[k], atol=1e-14)


def test_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(5)
    s = np.linspace(0.0, 1.0, 401)
    for _ in range(200):
        p1, q1, p2, q2 = rng.normal(size=(4, 3))
        if rng.random() < 0.2:
            q2 = p2 + (q1 - p1) * rng.uniform(0.5, 2)          # parallel segments
        exact = segment_distance(p1, q1, p2, q2)
        a = p1 + s[:, None] * (q1 - p1)
        b = p2 + s[:, None] * (q2 - p2)
        sampled = np.min(np.linalg.norm(a[:, None] - b[None], axis=2))
        assert exact <= sampled + 1e-12
        assert sampled - exact < 0.02 * np.linalg.norm(q1 - p1 + q2 - p2) + 1e-3
