"""The experiments' definitions that both the scenarios (over the bus) and the design tools
(in process) run: the thesis's two hexapod movements (chapter 11.3) as task-space waypoints
with their joint-space SLS trajectories, the timing of their approach, the bounds they are
held to, and the test bench's sine of chapter 7.6.2."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.kinematics import ik_batch
from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX, check_poses
from firmware_py.motion_control.trajectory import T_START, JointTrajectory, through_points
from protocol.codec import CODECS
from protocol.enums import WaypointFlag


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
    time_scale: float = 1.0            # x the thesis's timing (the approach's speed scales with it)

    def scaled(self, time_scale: float) -> Motion:
        """The same movement `time_scale` times slower (ta, tm and the approach scaled)."""
        return replace(self, ta_s=self.ta_s * time_scale, tm_s=self.tm_s * time_scale,
                       time_scale=self.time_scale * time_scale)

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


# -- the platform's movements (chapter 11.5) ------------------------------------------------
# the thesis ran these timings on the rig; the packaged waypoint limits are a safe default
# for operators, set for this experiment to what the actuators can do (~2.5 m/s at 10 V)
MOVEMENT_OVERRIDES = {"waypoints": {"velocity_max_mm_s": 1200.0},
                      "limits": {"velocity_max_mm_s": 1500.0}}
APPROACH_SPEED_M_S = 0.2
# `--time-scale` by the planner: "auto" the fastest timing the controller's capacity check
# accepts (faster than the thesis's where it can), "fit" the thesis's where it fits, else that
PLANNED_TIME_SCALES = ("auto", "fit")
IAE_FACTOR_MAX = 2.0                   # computed torque: IAE <= this x the thesis's model-based, every axis
MAX_ERROR_MM = 10.0                    # ... and its largest position error, every axis
# the thesis's IAE per axis (m s, Figs. 11.9-11.16) and timing of each movement
THESIS_MOVEMENTS = {
    "diagonal": {"iae_pi_plus_p": {"x": 0.071408, "y": 0.074467, "z": 0.1019},
                 "iae_model_based": {"x": 0.063427, "y": 0.064862, "z": 0.079075}, "ta_s": 0.05, "tm_s": 0.4},
    "circle": {"iae_pi_plus_p": {"x": 0.0070614, "y": 0.012584, "z": 0.0038265},
               "iae_model_based": {"x": 0.0069071, "y": 0.01151, "z": 0.003308}, "ta_s": 0.05, "tm_s": 0.25},
}


@dataclass(frozen=True)
class MovementWaypoint:
    position_m: np.ndarray
    segment_time_s: float
    accel_time_s: float
    flags: int


def movement_waypoints(motion: Motion) -> list[MovementWaypoint]:
    """The waypoints a host sends for the movement after its return home, as the controller
    decodes them (position and times at their signals' steps): each part a trajectory of its
    own, START on its first waypoint (it runs when the previous ends), LAST on its last."""
    out = []
    for p, part in enumerate(motion.parts):
        for k, point in enumerate(part[1:]):
            flags = (WaypointFlag.START if k == 0 else 0) | (WaypointFlag.LAST if k == len(part) - 2 else 0)
            out.append(on_the_wire(point, segment_time(motion, p, part[k], point), motion.ta_s, int(flags)))
    return out


def on_the_wire(position_m, segment_time_s: float, accel_time_s: float, flags: int) -> MovementWaypoint:
    """A waypoint as HOST_WAYPOINT_POS and _TIME carry it."""
    position, timing = CODECS["HOST_WAYPOINT_POS"], CODECS["HOST_WAYPOINT_TIME"]
    values = position.new_values()
    values[[position.index[a] for a in ("X", "Y", "Z")]] = position_m
    position.quantize_into(values, values)
    times = timing.new_values()
    times[timing.index["SEGMENT_TIME"]], times[timing.index["ACCEL_TIME"]] = segment_time_s, accel_time_s
    timing.quantize_into(times, times)
    return MovementWaypoint(values[[position.index[a] for a in ("X", "Y", "Z")]],
                            float(times[timing.index["SEGMENT_TIME"]]), float(times[timing.index["ACCEL_TIME"]]),
                            flags)


def segment_time(motion: Motion, part: int, start, end) -> float:
    """The thesis's tm, except the approach from home (part 0), whose timing the thesis does
    not give: at APPROACH_SPEED_M_S at the thesis's timing (0.25 s for 200 mm asks more than
    the actuators give), scaled with the rest, so a time scale slows every part alike."""
    if part > 0:
        return motion.tm_s
    distance = float(np.linalg.norm(np.asarray(end) - np.asarray(start)))
    return round(max(motion.tm_s, motion.time_scale * distance / APPROACH_SPEED_M_S), 3)


# -- the test bench's sine (chapter 7.6.2) ----------------------------------------------------
SINE_CENTRE_MM, SINE_AMPLITUDE_MM = 150.0, 125.0
SINE_POINTS_PER_PERIOD = 16
# The waypoint speed guard is for operators; this experiment asks up to 1.25 m/s (w = 10 rad/s).
TRACKING_OVERRIDES = {"waypoints": {"velocity_max_mm_s": 3000.0},
                      "limits": {"velocity_max_mm_s": 2500.0, "tracking_error_max_mm": 100.0}}
