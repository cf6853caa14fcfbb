"""The payload identified from the load cells (motion_control/payload.py): the regressor
against eq. 10.5's own dynamics with a payload, and the RLS on noisy load cells."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.rotation import quat_to_matrix_into, rpy_to_quat
from firmware_py.motion_control.payload import PayloadEstimator, payload_regressor_into

CFG = SimpleNamespace(forgetting=0.999, covariance_initial=0.01, covariance_max=0.01, mass_max_kg=30.0,
                      com_reach_m=0.3, innovation_max_n=300.0, com_mass_min_kg=0.3)


def _carrying(mass_kg: float, com_m):
    """The geometry with a point mass at `com_m` (platform frame) on the platform."""
    g = default_geometry()
    p = g.platform
    total = p.mass_kg + mass_kg
    com = (p.mass_kg * np.asarray(p.com_m) + mass_kg * np.asarray(com_m)) / total
    return replace(g, platform=replace(p, mass_kg=total, com_m=com))


def _cells(dynamics):
    """What the rods' load cells read (and the gravity along each leg): the actuators' forces
    less each rod's weight along its leg."""
    g = default_geometry()
    gravity_axial = dynamics.units @ -np.asarray(g.gravity_m_s2)
    return dynamics.force_n - g.rod.mass_kg * gravity_axial, gravity_axial


def _pose(rpy=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.62)):
    quat = rpy_to_quat(*rpy)
    rot = np.empty((3, 3))
    quat_to_matrix_into(quat, rot)
    return np.array(position, dtype=float), quat, rot


@pytest.mark.parametrize("accel", [(0.0, 0.0, 0.0), (0.8, -0.4, 1.5)])
def test_the_regressor_is_the_dynamics_own_payload_wrench(accel):
    mass, com = 2.5, np.array([0.04, -0.03, 0.06])
    position, quat, rot = _pose((0.08, -0.05, 0.3), (0.03, -0.02, 0.64))
    bare, loaded = InverseDynamics(default_geometry()), InverseDynamics(_carrying(mass, com))
    twist, a = np.zeros(6), np.concatenate([accel, np.zeros(3)])
    bare.forces(position, quat, twist, a)
    loaded.forces(position, quat, twist, a)
    wrench = bare.jacobian.T @ (loaded.force_n - bare.force_n)
    phi, prior = np.empty((6, 4)), np.array(default_geometry().platform.com_m)
    payload_regressor_into(rot, np.array(accel), np.array(default_geometry().gravity_m_s2), prior, phi)
    assert phi @ np.concatenate([[mass], mass * (com - prior)]) == pytest.approx(wrench, abs=1e-9)


def test_an_undeclared_payload_is_found_from_noisy_load_cells_while_holding():
    mass, com = 3.0, np.array([0.05, -0.04, 0.05])
    position, quat, rot = _pose()
    loaded = InverseDynamics(_carrying(mass, com))
    loaded.forces(position, quat, np.zeros(6), np.zeros(6))
    estimator = PayloadEstimator(default_geometry(), CFG, 0.0, np.zeros(3))
    rng = np.random.default_rng(3)
    cells, gravity_axial = _cells(loaded)
    for _ in range(1000):                                   # 2 s at 500 Hz; the emulator's cells: 0.3 N 1-sigma
        estimator.update(position, quat, rot, loaded.jacobian, gravity_axial, cells + rng.normal(0.0, 0.3, 6),
                         np.zeros(3))
    found = np.zeros(3)
    assert estimator.com_into(found)
    assert estimator.mass_kg == pytest.approx(mass, rel=0.05)
    assert found[:2] == pytest.approx(com[:2], abs=0.005)
    assert found[2] == pytest.approx(0.0, abs=1e-6)        # level and still: the height stays the prior's


def test_a_tilt_shows_the_height_and_a_reset_returns_to_the_declared_payload():
    mass, com = 3.0, np.array([0.02, 0.01, 0.08])
    estimator = PayloadEstimator(default_geometry(), CFG, 1.0, np.zeros(3))
    loaded = InverseDynamics(_carrying(mass, com))
    for rpy in ((0.0, 0.0, 0.0), (0.15, 0.0, 0.0), (0.0, -0.15, 0.0)):
        position, quat, rot = _pose(rpy)
        loaded.forces(position, quat, np.zeros(6), np.zeros(6))
        cells, gravity_axial = _cells(loaded)
        for _ in range(1000):
            estimator.update(position, quat, rot, loaded.jacobian, gravity_axial, cells, np.zeros(3))
    found = np.zeros(3)
    assert estimator.com_into(found) and found == pytest.approx(com, abs=0.002)
    estimator.reset()
    assert estimator.mass_kg == 1.0 and not estimator.samples


def test_a_load_cell_out_of_its_range_is_not_taken_for_a_payload():
    position, quat, rot = _pose()
    bare = InverseDynamics(default_geometry())
    bare.forces(position, quat, np.zeros(6), np.zeros(6))
    cells, gravity_axial = _cells(bare)
    estimator = PayloadEstimator(default_geometry(), CFG, 0.0, np.zeros(3))
    broken = cells.copy()
    broken[3] = 3200.0                                      # FORCE_LIMIT's kind of reading
    assert not estimator.update(position, quat, rot, bare.jacobian, gravity_axial, broken, np.zeros(3))
    assert estimator.mass_kg == 0.0 and estimator.samples == 0
    assert estimator.update(position, quat, rot, bare.jacobian, gravity_axial, cells, np.zeros(3))
