"""The per-cycle platform model of the hexapod rig: its in-place solver against NumPy, the
DK pose estimate, gravity along the legs and the reference forces against InverseDynamics."""

import numpy as np
import pytest

from firmware_py.mechanics.dynamics import InverseDynamics, gauss_solve_into
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import ik_batch
from firmware_py.mechanics.platform import PlatformModel
from firmware_py.mechanics.rotation import rpy_to_quat

G = default_geometry()


def test_gauss_solve_matches_numpy():
    rng = np.random.default_rng(4)
    lu, x = np.empty((6, 6)), np.empty(6)
    for _ in range(50):
        a, b = rng.standard_normal((6, 6)), rng.standard_normal(6)
        det = gauss_solve_into(a, b, lu, x, False)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
        assert det == pytest.approx(abs(np.linalg.det(a)), rel=1e-9)
        gauss_solve_into(a, b, lu, x, True)
        np.testing.assert_allclose(x, np.linalg.solve(a.T, b), rtol=1e-9, atol=1e-12)
    assert gauss_solve_into(np.zeros((6, 6)), np.ones(6), lu, x, False) == 0.0


def test_pose_estimate_gravity_and_reference_forces():
    pm = PlatformModel(G, 1e-7, 20, 0.002)
    position = np.array([0.03, -0.02, 0.62])
    quat = rpy_to_quat(0.05, -0.03, 0.1)
    lengths, units = ik_batch(G, position, quat)
    strokes = lengths[0] - G.leg_min_m
    assert pm.estimate(strokes)
    np.testing.assert_allclose(pm.dk.pose[:3], position, atol=1e-7)
    np.testing.assert_allclose(pm.gravity_axial, 9.81 * units[0][:, 2], rtol=1e-6)
    assert 0.0 < pm.det_ratio < 2.0
    # at rest along the reference: the static virtual-work forces
    pm.reset_reference(strokes)
    assert pm.reference_forces(strokes, np.zeros(6))
    dyn = InverseDynamics(G)
    assert dyn.forces(position, quat, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(pm.force_n, dyn.force_n, rtol=1e-5)
