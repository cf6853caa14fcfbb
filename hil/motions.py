"""The thesis's two hexapod movements (chapter 11.3) as task-space waypoints, and their
joint-space SLS trajectories through the controller's inverse kinematics."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from firmware_py.geometry import Geometry
from firmware_py.kinematics import ik_batch
from firmware_py.trajectory import T_START, JointTrajectory, through_points
from firmware_py.workspace import MIN_CONDITION_INDEX, check_poses


def concatenate(parts: list[JointTrajectory]) -> JointTrajectory:
    """Parts played one after the other (each part starts where and when the previous ended)."""
    chained = []
    offset = 0.0
    for part in parts:
        seg = part.segments.copy()
        seg[:, :, T_START] += offset
        chained.append(seg)
        offset += part.duration_s
    return JointTrajectory(np.concatenate(chained))


@dataclass
class Motion:
    """Task-space waypoints grouped in parts that start and end at rest, and their timing."""
    name: str
    parts: list[np.ndarray]            # each (n_points, 3) platform positions, orientation identity
    ta_s: float
    tm_s: float
    description: str

    def waypoints(self) -> np.ndarray:
        return np.concatenate([self.parts[0][:1]] + [part[1:] for part in self.parts])

    def joint_trajectory(self, geometry: Geometry) -> JointTrajectory:
        """Waypoints -> IK -> SLS joint profiles; raises ValueError for an unreachable waypoint."""
        pieces = []
        for part in self.parts:
            quats = np.tile([1.0, 0.0, 0.0, 0.0], (len(part), 1))
            report = check_poses(geometry, part, quats)
            bad = ~report.reachable | (report.condition_index < MIN_CONDITION_INDEX)
            if bad.any():
                raise ValueError(f"{self.name}: waypoint {part[np.argmax(bad)] * 1e3} mm is outside the "
                                 f"usable workspace")
            lengths, _ = ik_batch(geometry, part, quats)
            pieces.append(through_points(lengths, self.ta_s, self.tm_s))
        return concatenate(pieces)


# Movement I's cube (the thesis gives it only in plots: Fig. 11.8 spans about +/-0.1 m in x and
# y). Every vertex keeps >= 28 mm of stroke from both end stops; the largest cube inside the
# workspace (half side 120 mm about z = 675 mm) left one leg 5.8 mm from its extended end,
# where a 5 mm overshoot is a POSITION_LIMIT fault.
DIAGONAL_CENTRE_M = np.array([0.0, 0.0, 0.66])
DIAGONAL_HALF_SIDE_M = 0.1
CIRCLE_PLANE_Z_M = 0.631
CIRCLE_RADIUS_M = 0.2
CIRCLE_POINTS = 12


def diagonal_motion(geometry: Geometry) -> Motion:
    """Movement I: home -> cube centre -> each vertex and back to the centre (ta 50, tm 400 ms)."""
    home = geometry.home_position_m
    centre = DIAGONAL_CENTRE_M
    parts = [np.array([home, centre])]
    for signs in itertools.product((-1.0, 1.0), repeat=3):
        vertex = centre + DIAGONAL_HALF_SIDE_M * np.array(signs)
        parts.append(np.array([centre, vertex]))
        parts.append(np.array([vertex, centre]))
    return Motion("diagonal", parts, 0.05, 0.4,
                  "home -> cube centre -> each vertex of the cube and back to the centre, orientation fixed")


def circle_motion(geometry: Geometry) -> Motion:
    """Movement II: home -> start of the circle, then the circle in plane z = 631 mm (ta 50, tm 250 ms)."""
    home = geometry.home_position_m
    angles = np.linspace(0.0, 2 * np.pi, CIRCLE_POINTS + 1)
    circle = np.column_stack([CIRCLE_RADIUS_M * np.cos(angles), CIRCLE_RADIUS_M * np.sin(angles),
                              np.full(len(angles), CIRCLE_PLANE_Z_M)])
    return Motion("circle", [np.array([home, circle[0]]), circle], 0.05, 0.25,
                  "home -> start of the circle, then the circle in plane z = 631 mm; both parts end at rest")


MOTIONS = {"diagonal": diagonal_motion, "circle": circle_motion}
