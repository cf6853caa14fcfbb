"""The loop's mechanism kernels allocate no NumPy memory over 10,000 calls."""

import numpy as np

from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import DirectKinematics, ik_batch
from hil.experiments import diagonal_motion
from tests.support.alloc import allocations

GEOMETRY = default_geometry()


def test_ik_dk_dynamics_and_trajectory_allocate_nothing_per_cycle():
    traj = diagonal_motion(GEOMETRY).joint_trajectory(GEOMETRY)
    dk = DirectKinematics(GEOMETRY)
    dyn = InverseDynamics(GEOMETRY)
    lengths, vel, acc = np.empty(6), np.empty(6), np.empty(6)
    twist = np.array([0.1, 0.0, -0.1, 0.2, 0.1, 0.0])
    accel = np.array([1.0, -1.0, 0.5, 0.0, 2.0, 1.0])

    def cycle(k):
        traj.evaluate_into((k % 3400) * 0.002, lengths, vel, acc)
        dk.solve(lengths)
        dyn.forces(dk.pose[:3], dk.pose[3:], twist, accel)
        dyn.task_space_terms(dk.pose[:3], dk.pose[3:], twist)

    for k in range(100):
        cycle(k)

    def steady():
        for k in range(100, 10_100):
            cycle(k)

    grown, gained = allocations(steady)
    assert grown == []
    assert gained < 4096
    assert dk.converged and np.all(np.isfinite(dyn.force_n))
    # the DK followed the trajectory: its pose reproduces the commanded lengths
    assert np.allclose(ik_batch(GEOMETRY, dk.pose[:3], dk.pose[3:])[0][0], lengths, atol=1e-10)


def test_the_allocation_check_sees_numpy_temporaries():
    """The same measurement flags a function that keeps NumPy arrays (the check can fail)."""
    kept = []

    def keep():
        for _ in range(10):
            kept.append(ik_batch(GEOMETRY, GEOMETRY.home_position_m, GEOMETRY.home_quaternion))

    grown, gained = allocations(keep)
    assert any(s.count_diff > 0 for s in grown) and gained > 0
