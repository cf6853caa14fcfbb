"""The workspace figures of chapter 9.3 for a geometry: the dexterous, parallel-platform
and rotation extents, scanning outward from the centre with the controller's workspace test."""

from __future__ import annotations

import numpy as np

from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.rotation import axis_angle_to_quat, rpy_to_quat
from firmware_py.mechanics.workspace import check_poses

DEXTERITY_DEG = 25.0


def dexterity_orientations(limit_deg: float = DEXTERITY_DEG) -> np.ndarray:
    """The 27 roll-pitch-yaw combinations of {-limit, 0, +limit} (dexterous workspace test)."""
    grid = np.radians(np.array(np.meshgrid(*[[-limit_deg, 0.0, limit_deg]] * 3)).reshape(3, -1))
    return rpy_to_quat(grid[0], grid[1], grid[2])


def dexterous_mask(geometry: Geometry, positions_m: np.ndarray, limit_deg: float = DEXTERITY_DEG) -> np.ndarray:
    """True where every orientation of dexterity_orientations() is reachable at the position."""
    quats = dexterity_orientations(limit_deg)
    n, m = len(positions_m), len(quats)
    report = check_poses(geometry, np.repeat(positions_m, m, axis=0), np.tile(quats, (n, 1)))
    return report.reachable.reshape(n, m).all(axis=1)


def _extent(ok, step: float, limit: float) -> float:
    value = 0.0
    while value + step <= limit and ok(value + step):
        value += step
    return value


def workspace_extents(geometry: Geometry) -> dict:
    """The chapter 9.3 figures for this geometry, scanning outward from the centre."""
    one = lambda pos, quat=(1.0, 0.0, 0.0, 0.0): bool(check_poses(geometry, [pos], quat).reachable[0])  # noqa: E731
    rotation = lambda axis: lambda a: one([0.0, 0.0, 0.7], axis_angle_to_quat(axis, a))  # noqa: E731
    return {
        "dexterous_x_mm_at_z675": 1e3 * _extent(lambda x: dexterous_mask(geometry, np.array([[x, 0, 0.675]]))[0],
                                                0.005, 1.0),
        "dexterous_y_mm_at_z675": 1e3 * _extent(lambda y: dexterous_mask(geometry, np.array([[0, y, 0.675]]))[0],
                                                0.005, 1.0),
        "parallel_x_mm_at_z600": 1e3 * _extent(lambda x: one([x, 0.0, 0.6]), 0.005, 1.0),
        "parallel_y_mm_at_z600": 1e3 * _extent(lambda y: one([0.0, y, 0.6]), 0.005, 1.0),
        "roll_deg_at_z700": float(np.degrees(_extent(rotation([1, 0, 0]), np.radians(0.5), np.pi))),
        "pitch_deg_at_z700": float(np.degrees(_extent(rotation([0, 1, 0]), np.radians(0.5), np.pi))),
        "yaw_deg_at_z700": float(np.degrees(_extent(rotation([0, 0, 1]), np.radians(0.5), np.pi))),
        "yaw_neg_deg_at_z700": float(np.degrees(_extent(rotation([0, 0, -1]), np.radians(0.5), np.pi))),
    }
