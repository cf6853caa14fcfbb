"""The time-optimal timing of a movement's path under the legs' force capacity (toppra's
TOPP-RA), beside the SLS timing the controller accepts.

The path is the one the controller's SLS reference traces (each rest-to-rest part in task
space: the platform's position by direct kinematics of the reference's strokes, orientation
held), splined. The constraint is second order in the path parameter: each leg's force
(eq. 10.5's inverse dynamics with the payload) within `share` of its capacity, the capacity
fitted as F0 - k v^2 in the direction of motion (the valve's orifice law; F0 at rest, k the
smallest that keeps the fit below the capacity over the grid) and F0 in the other. The
power unit's is first order: the chambers' flows (A extending, alpha A retracting) within the
pump's, a bound on the path speed at each point (`FlowBound`; the valves' leakage, which the
controller's check counts as well, left out: a lower bound). No lag and no
accumulator are allowed here: bounds the controller's check, which lets a brief peak through
and draws on the accumulator's reserve, may beat; with neither, it cannot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import DirectKinematics
from firmware_py.motion_control.trajectory import through_points
from firmware_py.supervision.capacity import LegCapacity, leg_capacity
from hil.experiments import Motion
from physics.hydraulics import HP_ALPHA, HP_AREA_A
from physics.power_unit import PU_PUMP

PATH_SAMPLES = 60                  # spline knots per part
GRID_POINTS = 200                  # TOPP-RA's grid per part
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


@dataclass
class QuadraticCapacity:
    """Per direction: F0 at rest and k with F0 - k v^2 below the capacity while moving that way."""
    push_rest_n: float
    push_k: float
    pull_rest_n: float            # > 0: the magnitude
    pull_k: float

    @classmethod
    def fit(cls, capacity: LegCapacity) -> QuadraticCapacity:
        v = capacity.velocities_m_s

        def side(values: np.ndarray, moving: np.ndarray) -> tuple[float, float]:
            rest = float(np.interp(0.0, v, values))
            ok = moving & np.isfinite(values)
            return abs(rest), float(np.max((abs(rest) - np.abs(values[ok])) / v[ok] ** 2))

        push = side(capacity.push_n, v > 0.05)
        pull = side(capacity.pull_n, v < -0.05)
        return cls(push[0], max(push[1], 0.0), pull[0], max(pull[1], 0.0))


class LegForces:
    """w(x, xd, xdd) for toppra: the legs' forces plus the capacity's v^2 terms, pushing then
    pulling, so that w <= g says each leg is within its share either way."""

    def __init__(self, geometry, capacity: QuadraticCapacity, share: float):
        self.dynamics = InverseDynamics(geometry)
        self.capacity, self.share = capacity, share
        self.twist, self.accel = np.zeros(6), np.zeros(6)

    def __call__(self, x, xd, xdd) -> np.ndarray:
        dyn, c = self.dynamics, self.capacity
        self.twist[0:3], self.accel[0:3] = xd, xdd
        dyn.forces(np.asarray(x, float), IDENTITY, self.twist, self.accel)
        velocity = dyn.jacobian @ self.twist
        extending, retracting = np.maximum(velocity, 0.0), np.minimum(velocity, 0.0)
        return np.concatenate([dyn.force_n + self.share * c.push_k * extending ** 2,
                               -dyn.force_n + self.share * c.pull_k * retracting ** 2])

    def limits(self) -> np.ndarray:
        c = self.capacity
        return self.share * np.concatenate([np.full(6, c.push_rest_n), np.full(6, c.pull_rest_n)])


class FlowBound:
    """toppra's velocity bounds along a task-space path for the pump: the path speed at which
    the legs' flows take the pump's flow, as each coordinate's bound there."""

    def __init__(self, geometry, path, capacity: LegCapacity):
        self.dynamics, self.path = InverseDynamics(geometry), path
        budget = capacity.supply
        self.area, self.alpha = float(budget.hydraulics[HP_AREA_A]), float(budget.hydraulics[HP_ALPHA])
        self.flow = float(budget.power[PU_PUMP])
        self.twist = np.zeros(6)

    def __call__(self, s: float) -> np.ndarray:
        x, tangent = self.path(s), self.path(s, 1)
        self.twist[0:3] = tangent
        self.dynamics.task_space_terms(np.asarray(x, float), IDENTITY, self.twist)
        rate = self.dynamics.jacobian @ self.twist                 # the legs' velocities per unit path speed
        drawn = float(np.sum(np.where(rate > 0.0, self.area * rate, -self.alpha * self.area * rate)))
        speed = self.flow / drawn if drawn > 0.0 else 1e6
        bound = np.maximum(np.abs(tangent) * speed, 1e-9)[:, None]
        return np.hstack([-bound, bound])


def part_path(part: np.ndarray, motion: Motion, geometry):
    """The task-space path the SLS reference of one part traces, splined over its length
    (the SLS's own time stands still at both ends: a path parameter must not); and the SLS's
    duration at scale 1."""
    import toppra

    from firmware_py.mechanics.kinematics import ik_batch
    lengths, _ = ik_batch(geometry, part, np.tile(IDENTITY, (len(part), 1)))
    trajectory = through_points(lengths, motion.ta_s, motion.tm_s)
    times = np.linspace(0.0, trajectory.duration_s, PATH_SAMPLES)
    dk = DirectKinematics(geometry, 1e-9, 50)
    positions = np.empty((len(times), 3))
    for k, (length, _, _) in enumerate(zip(*trajectory.sample(times))):
        dk.solve(length)
        positions[k] = dk.pose[0:3]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])
    return toppra.SplineInterpolator(arc, positions), trajectory.duration_s


def time_optimal(cfg: ControllerConfig, motion: Motion, payload_kg: float = 0.0) -> list[tuple[float, float]]:
    """Per part after the approach: (TOPP-RA's time-optimal duration, the SLS's at scale 1)."""
    import toppra
    import toppra.algorithm
    import toppra.constraint
    toppra.setup_logging("WARNING")
    geometry = default_geometry().with_payload(payload_kg)
    capacity = leg_capacity(cfg)
    forces = LegForces(geometry, QuadraticCapacity.fit(capacity), cfg.waypoints.capacity_share)
    identity12, g = np.eye(12), forces.limits()
    constraint = toppra.constraint.SecondOrderConstraint(
        forces, lambda x: identity12, lambda x: g, dof=3,
        discretization_scheme=toppra.constraint.DiscretizationType.Interpolation)
    out = []
    for part in motion.parts[1:]:
        path, sls_s = part_path(part, motion, geometry)
        constraints = [constraint]
        if capacity.supply is not None:
            constraints.append(toppra.constraint.JointVelocityConstraintVarying(
                FlowBound(geometry, path, capacity)))
        instance = toppra.algorithm.TOPPRA(constraints, path,
                                           gridpoints=np.linspace(*path.path_interval, GRID_POINTS))
        timed = instance.compute_trajectory(0.0, 0.0)
        out.append((float("nan") if timed is None else float(timed.duration), sls_s))
    return out
