"""What the legs can give against what a reference asks of them.

A leg's force capacity at its velocity (`physics.hydraulics.capacity_table`: the valve fully
open, the chambers in steady state, the seals' steady friction taken off), a share of it
kept for the control. Along a joint trajectory: each leg's static force (gravity, eq. 10.5 at
rest), its dynamic force (inertia and velocity terms) and its velocity. Slowing a path's
time by a factor s divides the velocities by s and the dynamic forces by s^2, so one
sampling at s = 1 answers every time scale.

The power unit is shared: what the valves draw (at each leg's force and velocity, the valve
map's steady state: the chamber it fills, the leakage, the underlaps) beyond the pump's flow
empties the accumulator and the line, and the supply may fall no further than its floor, a
share of its set pressure (`SupplyBudget`: the oil that gives, `physics.power_unit`).

The judgement is the lag a force shortfall leaves: where a leg needs more than its share,
the missing force over its joint-space inertia accelerates the leg behind its reference;
where it has spare force, that spare brings the lag's rate back to zero, after the chain's
end with the spare its last pose leaves. A brief peak (the
SLS's 50 ms acceleration) leaves a fraction of a millimetre; a sustained one (a payload's
weight at speed) grows without bound. What is left at a chain's end is where a chain that
starts as it ends starts from (turning back at a corner asks the same force direction on
both sides of the waypoint). A reference whose largest lag stays within the configured
bound is within capacity. Events only (commits, design): these allocate.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from firmware_py.mechanics.dynamics import InverseDynamics, gauss_solve_into, platform_wrench_into
from firmware_py.mechanics.kinematics import DirectKinematics, dk_solve_into, ik_into, jacobian_into
from firmware_py.motion_control.computed_torque import valve_map_eval
from firmware_py.motion_control.trajectory import sls_evaluate_into
from firmware_py.supervision.stages import Stages, at_once
from physics import hydraulics as hy
from physics import lugre
from physics import power_unit as pu

VELOCITY_GRID_M_S = np.linspace(-3.0, 3.0, 241)     # 25 mm/s apart; the valve's no-load speed is ~3.4 m/s
SCALE_RANGE = (0.25, 16.0)                         # the time scales a search spans
LOAD_SAMPLES_PER_STAGE = 8                         # a staged load computation: ~0.1 ms a stage here
LAG_STATE_ROWS, LAG_DIRECTION = 3, 2               # a lag state: rows rate, lag, direction (per leg)


@functools.lru_cache(maxsize=16)
def _table(ps: float, hp: bytes, friction: bytes) -> tuple[np.ndarray, np.ndarray]:
    """(push, pull) over the grid; cached: the chambers' steady states take ~0.5 s to solve."""
    hp_vector, fp = np.frombuffer(hp), np.frombuffer(friction)
    table = hy.capacity_table(VELOCITY_GRID_M_S, ps, hp_vector)
    steady = np.array([lugre.steady_friction(float(v), fp) for v in VELOCITY_GRID_M_S])
    return table[:, 0] - steady, table[:, 1] - steady


@dataclass
class SupplyBudget:
    """The power unit behind the legs (`physics.power_unit` vector `power`, set at the supply)
    and what each valve draws from it: the P edges' flow at the steady state the valve map
    holds at the leg's force and velocity (the chamber it fills, the leakage, the underlaps)."""
    power: np.ndarray
    hydraulics: np.ndarray
    friction: np.ndarray             # the seals' (LuGre vector): the piston gives the leg's force and theirs
    valve_map: tuple                 # (force_n, velocity_m_s, spool, pressure_a_pa, pressure_b_pa) at the supply
    floor_share: float               # the supply may fall to this share of its set pressure

    def reserve_m3(self) -> float:
        """The oil the line and accumulator give before the supply falls to its floor."""
        set_pa = float(self.power[pu.PU_SET])
        return pu.usable_volume(self.power, set_pa, self.floor_share * set_pa)

    def deficit_m3(self, force_n: np.ndarray, velocity_m_s: np.ndarray, dt_s: float,
                   initial_m3: float = 0.0) -> tuple[float, float]:
        """(the largest volume the valves draw beyond the pump's flow, the volume at the end),
        from `initial_m3` already drawn (the margin is kept on the pressure the accumulator may
        fall to, `reserve_m3`)."""
        return largest_deficit(force_n, velocity_m_s, dt_s, *self.valve_map, self.hydraulics, self.friction,
                               float(self.power[pu.PU_SET]), float(self.power[pu.PU_PUMP]), initial_m3)


@njit(cache=True)
def largest_deficit(force_n, velocity_m_s, dt_s, forces, velocities, spool, pressure_a, pressure_b, hp, fp,
                    supply_pa, pump_m3_s, initial_m3):
    """The valves' draw beyond `pump_m3_s`, integrated from `initial_m3` and never below zero
    (the pump refills the accumulator with its spare): (its largest value, its last) [m^3]."""
    deficit = worst = initial_m3
    for k in range(force_n.shape[0]):
        drawn = 0.0
        for leg in range(force_n.shape[1]):
            v = velocity_m_s[k, leg]
            f = force_n[k, leg] + lugre.steady_friction(v, fp)
            flow, _ = hy.supply_flow(valve_map_eval(forces, velocities, spool, f, v),
                                     valve_map_eval(forces, velocities, pressure_a, f, v),
                                     valve_map_eval(forces, velocities, pressure_b, f, v), supply_pa, hp, 1.0)
            drawn += flow
        deficit = max(deficit + (drawn - pump_m3_s) * dt_s, 0.0)
        worst = max(worst, deficit)
    return worst, deficit


@dataclass
class LegCapacity:
    """One leg's force range [N] over the velocity grid, net of the seals' steady friction, and
    the power unit all the legs share (None: an ideal supply)."""
    velocities_m_s: np.ndarray
    push_n: np.ndarray               # the largest force toward extension (NaN: beyond the valve's speed)
    pull_n: np.ndarray               # the smallest (most negative)
    supply: SupplyBudget | None = None

    @classmethod
    def of(cls, hydraulics: np.ndarray, friction: np.ndarray, supply_pa: float,
           power: np.ndarray | None = None, valve_map: tuple | None = None,
           floor_share: float | None = None) -> LegCapacity:
        """`power`, `valve_map` (at `supply_pa`) and `floor_share` all or none (an ideal supply)."""
        if (power is None) != (floor_share is None):
            raise ValueError("a power unit needs the share of its set pressure it may fall to, and only it")
        push, pull = _table(float(supply_pa), np.asarray(hydraulics, float).tobytes(),
                            np.asarray(friction, float).tobytes())
        budget = None if power is None else SupplyBudget(np.asarray(power, float), np.asarray(hydraulics, float),
                                                         np.asarray(friction, float), valve_map, floor_share)
        return cls(VELOCITY_GRID_M_S, push, pull, budget)

    def limits(self, velocity_m_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(push, pull) at each velocity; NaN beyond the grid or the valve's speed."""
        nan = math.nan
        return (np.interp(velocity_m_s, self.velocities_m_s, self.push_n, left=nan, right=nan),
                np.interp(velocity_m_s, self.velocities_m_s, self.pull_n, left=nan, right=nan))

    def utilisation(self, force_n: np.ndarray, velocity_m_s: np.ndarray) -> np.ndarray:
        """Each force's ratio to what the leg gives at its velocity in its direction (inf
        where it cannot: beyond the valve's speed, or a side that no longer reaches zero)."""
        push, pull = self.limits(velocity_m_s)
        pushing = force_n >= 0.0
        limit = np.where(pushing, push, pull)
        reaches = np.isfinite(limit) & np.where(pushing, limit > 0.0, limit < 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(reaches, force_n / limit, np.inf)


@dataclass
class Loads:
    """A trajectory's demands on the legs at time scale 1, sampled `dt_s` apart."""
    dt_s: float
    static_n: np.ndarray             # (n, legs) gravity alone
    dynamic_n: np.ndarray            # (n, legs) inertia and velocity terms
    velocity_m_s: np.ndarray         # (n, legs)
    inertia_kg: np.ndarray           # (n, legs) each leg's joint-space inertia, the others held
    to_platform: np.ndarray          # (n, 6, legs) the legs' errors to the platform's pose (Jx^-1);
                                     # (0, 6, legs): no platform, the legs' own
    angle_weight: float = 0.0        # m per rad: a rotation error this large counts as that position error
    ends_at_rest: bool = True        # False: the chain goes on (a lag still growing at the end carries on)

    def at_scale(self, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """(force, velocity) when the trajectory's time runs `scale` x slower."""
        return self.static_n + self.dynamic_n / (scale * scale), self.velocity_m_s / scale


@dataclass
class Judgement:
    within: bool
    lag_m: float                     # the largest lag a shortfall leaves (inf: a leg cannot at all)
    utilisation: float               # the largest force / capacity ratio (the share not applied)
    sample: int                      # where the lag (or the impossibility) peaks ...
    leg: int                         # ... and which leg (0-based)
    deficit_m3: float = 0.0          # the oil drawn beyond the pump's share (0: an ideal supply) ...
    reserve_m3: float = math.inf     # ... and what the accumulator and line give for it ...
    end_deficit_m3: float = 0.0      # ... and what is still drawn at the end
    end_lag: np.ndarray | None = None  # the lag state at the last sample (`lag_of`: the next chain's start)


def lag_state(legs: int) -> np.ndarray:
    """No lag: (rate, lag, direction) per leg, the legs on their reference."""
    state = np.zeros((LAG_STATE_ROWS, legs))
    state[LAG_DIRECTION] = 1.0
    return state


def shortfall_lag(capacity: LegCapacity, loads: Loads, scale: float, share: float,
                  initial_lag: np.ndarray | None = None) -> tuple[float, int, int, np.ndarray]:
    """(largest error [m], sample, leg, the lag state at the last sample) the legs' shortfalls
    leave at `scale`, each leg with `share` of its capacity (`lag_of`: the platform's position
    error where there is one), from `initial_lag` (a chain before it still behind; None: on
    the reference). inf where a leg cannot give that force at all."""
    state = lag_state(loads.static_n.shape[1]) if initial_lag is None else np.array(initial_lag, dtype=float)
    force, velocity = loads.at_scale(scale)
    push, pull = capacity.limits(velocity)
    push, pull = push * share, pull * share
    if not (np.isfinite(push).all() and np.isfinite(pull).all()):
        k, leg = np.unravel_index(int(np.argmax(~(np.isfinite(push) & np.isfinite(pull)))), push.shape)
        return math.inf, int(k), int(leg), state
    # the force beyond the leg's range (> 0 behind in its direction), or the spare (< 0)
    excess = np.where(force >= 0.0, force - push, pull - force)
    worst, at, leg = lag_of(excess, force, loads.inertia_kg, loads.dt_s * scale, loads.to_platform,
                            loads.angle_weight, state)
    if not loads.ends_at_rest:         # the chain goes on: its next segment takes the lag from here
        return worst, at, leg, state
    # holding the last pose: what its weight leaves each leg toward the force it lacked
    push_rest, pull_rest = capacity.limits(np.zeros_like(velocity[-1]))
    held = loads.static_n[-1]
    spare = np.where(state[LAG_DIRECTION] > 0.0, share * push_rest - held, held - share * pull_rest)
    settled, settled_leg = settled_lag(spare, loads.inertia_kg[-1], loads.to_platform[-1:], loads.angle_weight,
                                       state)
    if settled > worst:
        worst, at, leg = settled, excess.shape[0] - 1, settled_leg
    return worst, at, leg, state


@njit(cache=True)
def lag_of(excess_n, force_n, inertia_kg, dt_s, to_platform, angle_weight, state):
    """(largest error, sample, leg): per leg, the lag's rate grows by the excess over the
    inertia and never below zero, the lag by the rate and back to zero with it (the position
    loop takes what is left), behind in the direction of the force it lacked. `state` (rows
    rate, lag, direction) is where it starts and is left where the last sample ends: a chain
    that starts as this one ends starts from it. The error is the platform's position error
    these lags make (`to_platform[k]` (3, legs): the position rows of Jx^-1; the rotation's,
    weighted by `angle_weight` m/rad, as well: the larger of the two), or the largest lag
    where there is no platform (`to_platform` empty)."""
    n, legs = excess_n.shape
    rate, lag, direction = state[0].copy(), state[1].copy(), state[2].copy()
    worst, at, leg_at = 0.0, 0, 0
    for k in range(n):
        for leg in range(legs):
            if rate[leg] == 0.0 and excess_n[k, leg] > 0.0:      # a shortfall begins: behind which way
                direction[leg] = 1.0 if force_n[k, leg] >= 0.0 else -1.0
            rate[leg] = max(rate[leg] + excess_n[k, leg] / inertia_kg[k, leg] * dt_s, 0.0)
            lag[leg] = lag[leg] + rate[leg] * dt_s if rate[leg] > 0.0 else 0.0
        error, largest = lags_error(to_platform, k, angle_weight, direction, lag)
        if error > worst:
            worst, at, leg_at = error, k, largest
    state[0, :], state[1, :], state[2, :] = rate, lag, direction
    return worst, at, leg_at


@njit(cache=True)
def lags_error(to_platform, k, angle_weight, direction, lag):
    """(the error the legs' lags make at sample k, the leg lagging most): `lag_of`'s."""
    legs = lag.shape[0]
    largest = 0
    for leg in range(legs):
        if lag[leg] > lag[largest]:
            largest = leg
    if to_platform.shape[0] == 0:
        return lag[largest], largest
    position = angle = 0.0
    for axis in range(6):
        component = 0.0
        for leg in range(legs):
            component += to_platform[k, axis, leg] * direction[leg] * lag[leg]
        if axis < 3:
            position += component * component
        else:
            angle += component * component
    return max(math.sqrt(position), angle_weight * math.sqrt(angle)), largest


@njit(cache=True)
def settled_lag(spare_n, inertia_kg, to_platform, angle_weight, state):
    """(the error, the leg lagging most) once the legs have stopped falling behind after the
    chain's end, holding its last pose: a leg still losing ground there (rate > 0) is brought
    back only by the spare its share leaves over that pose's weight toward the force it lacked
    (`spare_n`), adding rate^2 / (2 spare / inertia) to its lag (each leg at its most at once:
    an upper bound); inf where it has none. A pose held near a leg's limit leaves it almost
    nothing to stop a lag with. `state` is not changed."""
    rate, lag, direction = state[0], state[1].copy(), state[2]
    for leg in range(lag.shape[0]):
        if rate[leg] > 0.0:
            if spare_n[leg] <= 0.0:
                return math.inf, leg
            lag[leg] += rate[leg] * rate[leg] * inertia_kg[leg] / (2.0 * spare_n[leg])
    return lags_error(to_platform, 0, angle_weight, direction, lag)


def supply_deficit(capacity: LegCapacity, loads: Loads, scale: float,
                   initial_m3: float = 0.0) -> tuple[float, float, float]:
    """(the oil drawn beyond the pump's flow, the reserve for it, what is drawn at the end)
    [m^3] at `scale`, from `initial_m3` drawn before (the motions before it)."""
    budget = capacity.supply
    if budget is None:
        return 0.0, math.inf, 0.0
    force, velocity = loads.at_scale(scale)
    worst, end = budget.deficit_m3(force, velocity, loads.dt_s * scale, initial_m3)
    return worst, budget.reserve_m3(), end


def fits(capacity: LegCapacity, loads: Loads, scale: float, share: float, lag_max_m: float,
         initial_m3: float = 0.0, initial_lag: np.ndarray | None = None) -> bool:
    """Within capacity at `scale`: the lag within its bound and the supply within its reserve."""
    deficit, reserve, _ = supply_deficit(capacity, loads, scale, initial_m3)
    return deficit <= reserve and shortfall_lag(capacity, loads, scale, share, initial_lag)[0] <= lag_max_m


def judge(capacity: LegCapacity, loads: Loads, scale: float, share: float, lag_max_m: float,
          initial_m3: float = 0.0, initial_lag: np.ndarray | None = None) -> Judgement:
    return at_once(judge_stages(capacity, loads, scale, share, lag_max_m, initial_m3, initial_lag))


def judge_stages(capacity: LegCapacity, loads: Loads, scale: float, share: float, lag_max_m: float,
                 initial_m3: float = 0.0, initial_lag: np.ndarray | None = None) -> Stages[Judgement]:
    """`judge` in three stages: the lag, the supply, the utilisation."""
    lag, k, leg, end_lag = shortfall_lag(capacity, loads, scale, share, initial_lag)
    yield
    deficit, reserve, end = supply_deficit(capacity, loads, scale, initial_m3)
    yield
    force, velocity = loads.at_scale(scale)
    ratio = capacity.utilisation(force, velocity)
    return Judgement(lag <= lag_max_m and deficit <= reserve, lag, float(np.max(ratio)), k, leg, deficit, reserve,
                     end, end_lag)


def needed_scale(capacity: LegCapacity, loads: Loads, share: float, lag_max_m: float,
                 tolerance: float = 0.005, beyond: float | None = None, initial_m3: float = 0.0,
                 initial_lag: np.ndarray | None = None) -> float:
    """The smallest time scale (within SCALE_RANGE) that `fits`; NaN when even the slowest
    does not (a static load the legs cannot hold, or a supply already drawn below its share).
    `beyond`: a scale known not to fit, the search's floor (near the bound `fits` is not
    monotonic: a refusal at 1 must not name 0.99)."""
    return at_once(needed_scale_stages(capacity, loads, share, lag_max_m, tolerance, beyond, initial_m3,
                                       initial_lag))


def needed_scale_stages(capacity: LegCapacity, loads: Loads, share: float, lag_max_m: float,
                        tolerance: float = 0.005, beyond: float | None = None,
                        initial_m3: float = 0.0, initial_lag: np.ndarray | None = None) -> Stages[float]:
    """`needed_scale`, a stage per time scale tried."""
    low, high = SCALE_RANGE
    if not fits(capacity, loads, high, share, lag_max_m, initial_m3, initial_lag):
        return math.nan
    yield
    if beyond is not None:
        low = beyond
    elif fits(capacity, loads, low, share, lag_max_m, initial_m3, initial_lag):
        return low
    while high - low > tolerance * low:
        yield
        middle = math.sqrt(low * high)
        if fits(capacity, loads, middle, share, lag_max_m, initial_m3, initial_lag):
            high = middle
        else:
            low = middle
    return high


def leg_loads(trajectory, t0_s: float, t1_s: float, dt_s: float, mass_kg: float, gravity_m_s2: float) -> Loads:
    """The test bench's vertical leg: (m + load)(g + a)."""
    times = np.arange(t0_s, t1_s + 0.5 * dt_s, dt_s)
    _, velocity, accel = trajectory.sample(times)
    static = np.full_like(velocity, mass_kg * gravity_m_s2)
    return Loads(dt_s, static, mass_kg * accel, velocity, np.full_like(velocity, mass_kg),
                 np.zeros((0, 6, velocity.shape[1])))


@njit(cache=True)
def platform_loads_into(segments, times, h, leg_min, base, platform, axis1, masses, coms, inertias, gravity,
                        tolerance, max_iterations, max_step_quat, home, q, dk_scratch, kin_scratch, vectors,
                        poses, jacobians, static, dynamic, velocity):
    """Per sample time: the pose (DK warm-started along the path), the twist from Jx xd = L'
    at t and t + h, eq. 10.5's forces at rest (static) and with the twist and its difference
    quotient (dynamic: the rest). Returns the first sample where DK or Jx fails, else -1."""
    rot, world, units, phi, gmat, jac7, normal, y, step, status = dk_scratch
    rot2, world2, units2, jac, lu = kin_scratch
    pos, vel, acc, lengths, lengths_ik, twist, twist_h, accel, wrench, force, zero = vectors
    for k in range(times.shape[0]):
        for later in (1, 0):                      # t + h first: q ends at the pose of t
            sls_evaluate_into(segments, times[k] + later * h, pos, vel, acc)
            for j in range(6):
                lengths[j] = pos[j] + leg_min
            dk_solve_into(base, platform, lengths, q, tolerance, max_iterations, max_step_quat,
                          rot, world, units, phi, gmat, jac7, normal, y, step, status)
            if status[2] != 1.0:
                q[:] = home
                dk_solve_into(base, platform, lengths, q, tolerance, max_iterations, max_step_quat,
                              rot, world, units, phi, gmat, jac7, normal, y, step, status)
                if status[2] != 1.0:
                    return k
            ik_into(base, platform, q[0:3], q[3:7], rot2, world2, lengths_ik, units2)
            jacobian_into(units2, world2, jac)
            if gauss_solve_into(jac, vel, lu, twist_h if later else twist, False) == 0.0:
                return k
        poses[k] = q
        jacobians[k] = jac
        velocity[k] = vel
        for j in range(6):
            accel[j] = (twist_h[j] - twist[j]) / h
        platform_wrench_into(base, platform, axis1, lengths_ik, units2, world2, rot2, masses, coms, inertias,
                             gravity, zero, zero, wrench)
        if gauss_solve_into(jac, wrench, lu, force, True) == 0.0:
            return k
        static[k] = force
        platform_wrench_into(base, platform, axis1, lengths_ik, units2, world2, rot2, masses, coms, inertias,
                             gravity, twist, accel, wrench)
        gauss_solve_into(jac, wrench, lu, force, True)
        for j in range(6):
            dynamic[k, j] = force[j] - static[k, j]
    return -1


class PlatformLoads:
    """The hexapod's legs along a joint trajectory of strokes (`platform_loads_into`), and
    each leg's joint-space inertia at the first, middle and last sample (the smallest)."""

    def __init__(self, geometry, tolerance_m: float, max_iterations: int = 50, h_s: float = 5e-4,
                 angle_weight: float = 0.0):
        self.geometry, self.h_s, self.angle_weight = geometry, h_s, angle_weight
        self.dk = DirectKinematics(geometry, tolerance_m, max_iterations)
        self.dynamics = InverseDynamics(geometry)
        dk = self.dk
        self._dk_scratch = (dk._rot, dk._platform_world, dk._units, dk._phi, dk._gmat, dk._jac, dk._normal,
                            dk._y, dk._step, dk.status)
        self._kin_scratch = (np.empty((3, 3)), np.empty((6, 3)), np.empty((6, 3)), np.empty((6, 6)),
                             np.empty((6, 6)))
        self._vectors = tuple(np.zeros(6) for _ in range(11))
        self._q = dk.home.copy()

    def loads(self, trajectory, t0_s: float, t1_s: float, dt_s: float) -> Loads:
        """ValueError naming the time where the path leaves the workspace or passes a singularity."""
        return at_once(self.loads_stages(trajectory, t0_s, t1_s, dt_s))

    def loads_stages(self, trajectory, t0_s: float, t1_s: float, dt_s: float) -> Stages[Loads]:
        """`loads` in stages of LOAD_SAMPLES_PER_STAGE samples (the DK warm-starts across them)."""
        g, dyn, dk = self.geometry, self.dynamics, self.dk
        times = np.arange(t0_s, t1_s + 0.5 * dt_s, dt_s)
        poses, jacobians = np.empty((len(times), 7)), np.empty((len(times), 6, 6))
        static, dynamic, velocity = (np.empty((len(times), 6)) for _ in range(3))
        for a in range(0, len(times), LOAD_SAMPLES_PER_STAGE):
            part = slice(a, a + LOAD_SAMPLES_PER_STAGE)
            failed = platform_loads_into(trajectory.segments, times[part], self.h_s, float(g.leg_min_m), dk.base,
                                         dk.platform, dyn.axis1, dyn.masses, dyn.coms, dyn.inertias, dyn.gravity,
                                         dk.tolerance_m, dk.max_iterations, dk.max_step_quat, dk.home, self._q,
                                         self._dk_scratch, self._kin_scratch, self._vectors, poses[part],
                                         jacobians[part], static[part], dynamic[part], velocity[part])
            if failed >= 0:
                raise ValueError(f"the path leaves the workspace or passes a singular pose at t = "
                                 f"{times[a + failed]:.3f} s")
            yield
        inertias = []
        for k in sorted({0, len(times) // 2, len(times) - 1}):
            inertias.append(self._leg_inertia(poses[k]))
            yield
        inertia = np.min(inertias, axis=0)
        return Loads(dt_s, static, dynamic, velocity, np.broadcast_to(inertia, static.shape),
                     np.linalg.inv(jacobians), self.angle_weight)

    def _leg_inertia(self, pose) -> np.ndarray:
        """diag(Jx^-T M Jx^-1): each leg's inertia with the other legs held."""
        dyn = self.dynamics
        dyn.task_space_terms(pose[0:3], pose[3:7], np.zeros(6))
        inverse = np.linalg.inv(dyn.jacobian)
        return np.einsum("ki,kl,li->i", inverse, dyn.mass_matrix, inverse)


def leg_capacity(cfg) -> LegCapacity:
    """The controller's legs: its [actuator] hydraulics and [friction] at the configured supply,
    on its [power_unit]."""
    supply_pa = cfg.hydraulic_model.supply_pressure_pa
    return LegCapacity.of(cfg.hydraulics, cfg.friction.vector, supply_pa, cfg.power, cfg.valve_map.at_supply(supply_pa),
                          cfg.waypoints.supply_share)
