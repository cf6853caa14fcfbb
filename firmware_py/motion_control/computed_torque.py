"""Computed-torque control of the hexapod through its hydraulics (beyond the thesis).

The thesis's controllers close a PI per leg. On this platform the legs stand near vertical:
a leg sees ~100 kg of joint-space inertia sideways and under 1 kg upwards, and a per-leg
loop cannot suit both (`hydrapod design modes`). Here the loop is closed on the platform's
pose, and the legs are driven through the inverse of their dynamics, in three steps:

1. task space (pose error e, twist error, reference acceleration a_r, eq. 10.5's virtual-work
   dynamics at the measured pose and twist):
       a_cmd = a_r + Kd (xd_r - xd) + Kp e + Ki int(e),   Kp = w^2, Kd = 2 zeta w, Ki = f w^3
       F_cmd = tau(pose, xd, a_cmd)                       (the legs' forces for a_cmd)
   the same closed-loop poles in every direction, whatever its inertia, but the yaw: the
   legs barely see it (`yaw_fusion.py`), so with the IMU's yaw and rate it has poles of its
   own, as fast as its light inertia allows (without a valid IMU, the legs' and the rest's);
2. each valve through its steady-state map (the spool that holds a leg at force F and
   piston velocity v), with the commanded velocity v_r + lambda e_leg and the compliance flow
   F_r' / K of the oil column (F_r the forces along the reference, differenced):
       x = map(F_cmd, v_r + lambda e_leg + F_r' / K) + k_F (F_cmd - F_load cell)
   lambda keeps the light directions stiff (the valve is a velocity source there), k_F closes
   a force loop on the load cells around the map's error and the seals' friction. In those
   light directions (z, roll, pitch) the PID's force barely moves the legs, so its integral
   cannot take out their lag there: it also joins their commanded velocity,
   v_r + lambda e_leg + J_s K_s int(e_s);
3. the spool to volts, saturated; the integral stops while a valve saturates, and while a
   leg's force command is beyond `windup_capacity_pct` of what its valve gives fully open at
   its reference's velocity (at the supply it reads): near rest a leg reaches that limit with
   its spool well inside u_max, and an integral wound up against it overshoots once the leg
   can follow again. Where valves
   are at their limit, the others' forces are chosen again (`reallocate_into`): the limited
   legs give what their load cells read, and the free ones keep the platform's acceleration
   error least, its rotations first, instead of the uneven shortfall turning it (the yaw's
   light inertia swung 4 deg in 50 ms of a corner's saturation).
Allocation-free; every array is made here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.config import ComputedTorqueGains, ControllerConfig
from firmware_py.mechanics.dynamics import InverseDynamics, gauss_solve_into
from firmware_py.mechanics.geometry import N_LEGS, Geometry
from firmware_py.mechanics.rotation import rotation_vector_between_into
from firmware_py.motion_control.estimation import filter_step, first_order_gain, second_order_filter
from firmware_py.motion_control.yaw_fusion import YawFusion, with_yaw_into
from physics import hydraulics as hy
from physics import lugre
from physics.constants import GRAVITY_M_S2


@njit(cache=True)
def pose_error_into(reference, measured, out) -> None:
    """out[0:3] = p_r - p, out[3:6] = rotation vector of R_r R^T (base frame); poses are
    (x, y, z, qw, qx, qy, qz)."""
    for k in range(3):
        out[k] = reference[k] - measured[k]
    rotation_vector_between_into(reference[3:7], measured[3:7], out[3:6])


@njit(cache=True)
def valve_map_eval(forces, velocities, spool, force, velocity) -> float:
    """Bilinear interpolation of the map, held at its edges."""
    nf, nv = forces.shape[0], velocities.shape[0]
    f = min(max(force, forces[0]), forces[nf - 1])
    v = min(max(velocity, velocities[0]), velocities[nv - 1])
    i = 0
    while i < nf - 2 and f > forces[i + 1]:
        i += 1
    j = 0
    while j < nv - 2 and v > velocities[j + 1]:
        j += 1
    s = (f - forces[i]) / (forces[i + 1] - forces[i])
    t = (v - velocities[j]) / (velocities[j + 1] - velocities[j])
    return ((1.0 - s) * ((1.0 - t) * spool[i, j] + t * spool[i, j + 1])
            + s * ((1.0 - t) * spool[i + 1, j] + t * spool[i + 1, j + 1]))


@njit(cache=True)
def task_acceleration_into(accel_ref, twist_ref, twist, error, integral, kp, kd, ki, out) -> None:
    """a_cmd = a_r + Kd (xd_r - xd) + Kp e + Ki int(e), each gain per direction."""
    for k in range(out.shape[0]):
        out[k] = accel_ref[k] + kd[k] * (twist_ref[k] - twist[k]) + kp[k] * error[k] + ki[k] * integral[k]


@njit(cache=True)
def spool_commands_into(force_map, force_cmd, force_ref, force_ref_prev, force_measured, velocity_ref, joint_error,
                        strokes_ref, period_s, velocity_gain, force_bandwidth, rate_floor, forces, velocities, spool,
                        pressure_a, pressure_b, hp, supply_pa, supply_ratio, u_max, stiffness, force_gain,
                        out) -> bool:
    """Each valve's spool (fraction of full input, saturated at u_max) from the map at the
    hydraulic force `force_map` and the force loop on the load cell (`force_cmd` its wanted
    reading); True when one saturated. Scheduled per leg on the reference's operating point
    (its force, velocity and stroke, the map's steady pressures and spool there): the oil
    column's stiffness K (`stiffness`, for the compliance flow F_r' / K) and the force loop's
    gain k_F = w_F / (dF'/dx) (`force_gain`), dF'/dx the force rate per spool there: the
    same bandwidth w_F wherever the leg stands. dF'/dx is taken no lower than `rate_floor`
    (the smallest at rest over the design's operating set): where a chamber nears the tank
    pressure its entrained air makes the rate collapse, and the pressures of a transient
    are not the map's steady ones. The map is `supply_pa`'s; each valve's supply is
    `supply_ratio[i]` r of it, read through the orifices' similarity (`hy.supply_similarity`:
    the spool holding F at v at r times the supply holds F / r at v / sqrt(r) at it, every
    pressure r times)."""
    saturated = False
    for i in range(out.shape[0]):
        r = supply_ratio[i]
        root = math.sqrt(r)
        f_ref, v_ref, y_ref = force_ref[i] / r, velocity_ref[i] / root, strokes_ref[i]
        pa = r * valve_map_eval(forces, velocities, pressure_a, f_ref, v_ref)
        pb = r * valve_map_eval(forces, velocities, pressure_b, f_ref, v_ref)
        k = hy.column_stiffness(y_ref, pa, pb, hp)
        stiffness[i] = k
        rate = hy.force_rate_per_spool(y_ref, pa, pb, valve_map_eval(forces, velocities, spool, f_ref, v_ref),
                                       r * supply_pa, hp)
        force_gain[i] = force_bandwidth / max(rate, root * rate_floor)
        velocity = velocity_ref[i] + velocity_gain * joint_error[i] + (force_ref[i] - force_ref_prev[i]) / period_s / k
        x = (valve_map_eval(forces, velocities, spool, force_map[i] / r, velocity / root)
             + force_gain[i] * (force_cmd[i] - force_measured[i]))
        if abs(x) >= u_max:
            saturated = True
            x = u_max if x > 0.0 else -u_max
        out[i] = x
    return saturated


@njit(cache=True)
def reallocate_into(jacobian, force, measured, spool, u_max, weights, pin, wrench, normal, rhs, lu, out) -> bool:
    """With valves at their limit (|spool| >= u_max): the legs' forces whose wrench J^T f
    comes nearest the wanted one's (J^T `force`) in the `weights`' norm, the limited legs'
    pinned (`pin` relative) at what their load cells read: the free legs keep the directions
    weighted most. False (out untouched) when none is limited or fewer than two are free."""
    n = force.shape[0]
    limited = 0
    for i in range(n):
        if abs(spool[i]) >= u_max:
            limited += 1
    if limited == 0 or n - limited < 2:
        return False
    for k in range(6):
        total = 0.0
        for i in range(n):
            total += jacobian[i, k] * force[i]
        wrench[k] = total
    largest = 0.0
    for i in range(n):
        total = 0.0
        for k in range(6):
            total += jacobian[i, k] * weights[k] * wrench[k]
        rhs[i] = total
        for j in range(n):
            total = 0.0
            for k in range(6):
                total += jacobian[i, k] * weights[k] * jacobian[j, k]
            normal[i, j] = total
        largest = max(largest, normal[i, i])
    for i in range(n):
        if abs(spool[i]) >= u_max:
            normal[i, i] += pin * largest
            rhs[i] += pin * largest * measured[i]
    return gauss_solve_into(normal, rhs, lu, out, False) > 0.0


@njit(cache=True)
def largest_abs(values) -> float:
    largest = 0.0
    for v in values:
        largest = max(largest, abs(v))
    return largest


@njit(cache=True)
def supply_ratio_into(supply_pa, nominal_pa, alpha, out) -> None:
    """out += alpha (p_s / nominal - out) per valve, a reading below a tenth of nominal as 1."""
    for i in range(out.shape[0]):
        ratio = supply_pa[i] / nominal_pa
        out[i] += alpha * ((ratio if ratio > 0.1 else 1.0) - out[i])


@njit(cache=True)
def low_pass_into(raw, state, ad, bd, wn, zeta, out) -> None:
    """out = F(s) raw per component (2nd order, state rows [x, x', u_prev]); advances F."""
    for k in range(raw.shape[0]):
        filter_step(state[k], ad, bd, wn, zeta, raw[k])
        out[k] = state[k, 0]


@njit(cache=True)
def blend_into(a, b, weight, out) -> None:
    """out = a + weight (b - a)."""
    for k in range(out.shape[0]):
        out[k] = a[k] + weight * (b[k] - a[k])


@njit(cache=True)
def leg_forces_into(accel_cmd, accel_ref, load_force, force_measured, velocity_ref, joint_error, velocity_gain,
                    rod_mass, friction, force_map, force_cmd, force_ref) -> None:
    """One actuator lifting a load it weighs on its load cell (the test bench): the load's
    mass from the cell's low-passed force F_lp, m = F_lp / g;
        F_cmd = F + m a_cmd                   (the cell's wanted reading: the force loop adds m a_cmd)
        F_map = F_lp + (m_rod + m) a_cmd + m_rod g + F_ss(v_r + lambda e)   (the piston's force)
        F_ref = (m_rod + m) (a_r + g)                               (along the reference)
    with F_ss the seals' steady friction (eq. 6.4) at the commanded velocity. The force loop
    has no part that opposes the cell's own swings: on this leg that pressure feedback made
    the steps overshoot more (13 % against 5 % with 6 kg, docs/MEASUREMENTS.md)."""
    for i in range(force_map.shape[0]):
        mass = max(load_force[i], 0.0) / GRAVITY_M_S2
        force_cmd[i] = force_measured[i] + mass * accel_cmd[i]
        seals = lugre.steady_friction(velocity_ref[i] + velocity_gain * joint_error[i], friction)
        force_map[i] = load_force[i] + (rod_mass + mass) * accel_cmd[i] + rod_mass * GRAVITY_M_S2 + seals
        force_ref[i] = (rod_mass + mass) * (accel_ref[i] + GRAVITY_M_S2)


@njit(cache=True)
def backward_difference_into(position, period_s, previous, rate) -> None:
    """rate = (position - previous) / T, then previous = position: unbiased, where the
    adaptive Kalman filter's lag at low speed is ~10x larger in x and y through J^-1
    (docs/EQUATIONS.md "Computed torque"); the twist's low-pass takes out the counts."""
    for i in range(rate.shape[0]):
        rate[i] = (position[i] - previous[i]) / period_s
        previous[i] = position[i]


@njit(cache=True)
def first_order_into(raw, alpha, state) -> None:
    """state += alpha (raw - state): a first-order low-pass (alpha: `first_order_gain`)."""
    for i in range(state.shape[0]):
        state[i] += alpha * (raw[i] - state[i])


STIFF_FIRST, STIFF_COUNT = 2, 3       # z, roll, pitch: the pose error's stiff directions (twist order)


@njit(cache=True)
def stiff_velocity_into(jacobian, integral, origin, gain, velocity_gain, joint_error, out) -> None:
    """out = e_leg + J_s K_s (int(e_s) - origin) / lambda: the PID's integral in the stiff
    directions (z, roll, pitch; m s and rad s), counted from `origin`, as the legs' equivalent
    position error, which the velocity loop turns into J_s K_s (int(e_s) - origin) of
    commanded velocity."""
    scale = gain / velocity_gain
    for i in range(out.shape[0]):
        extra = 0.0
        for k in range(STIFF_FIRST, STIFF_FIRST + STIFF_COUNT):
            extra += jacobian[i, k] * (integral[k] - origin[k - STIFF_FIRST])
        out[i] = joint_error[i] + scale * extra


@njit(cache=True)
def stiff_origin_step(integral, alpha, origin) -> None:
    """origin += alpha (int(e_s) - origin): at rest the velocity's share fades (alpha: one
    cycle of a first-order lag)."""
    for k in range(STIFF_COUNT):
        origin[k] += alpha * (integral[STIFF_FIRST + k] - origin[k])


@njit(cache=True)
def force_range_at(velocity_m_s, supply_ratio, grid_m_s, push_n, pull_n, pushing) -> float:
    """A leg's force with its valve fully open that way at its velocity: push or pull over
    `grid_m_s` at the configured supply (held at the grid's ends; NaN: a speed the open valve
    cannot reach), at `supply_ratio` r of it through the orifices' similarity, r F(v / sqrt(r))."""
    root = math.sqrt(supply_ratio)
    return supply_ratio * np.interp(velocity_m_s / root, grid_m_s, push_n if pushing else pull_n)


@njit(cache=True)
def beyond_force_range(force, velocity, supply_ratio, grid, push, pull, share) -> bool:
    """True when a leg's force exceeds `share` of its range at its velocity (`force_range_at`;
    a NaN range is exceeded)."""
    for i in range(force.shape[0]):
        pushing = force[i] >= 0.0
        limit = share * force_range_at(velocity[i], supply_ratio[i], grid, push, pull, pushing)
        if not (force[i] <= limit if pushing else force[i] >= limit):      # NaN: beyond
            return True
    return False


@njit(cache=True)
def integrate_into(integral, error, period_s) -> None:
    for k in range(integral.shape[0]):
        integral[k] += error[k] * period_s


FILTER_ZETA = 0.7                     # the measured twist's low-pass: Butterworth-like
# the force loops' bandwidth follows the reference: resting below this leg speed, over this time
RESTING_M_S = 1e-4
FORCE_SCHEDULE_S = 0.1
# the supply the map is read at follows the P-port samples this slowly: a sag, not the dips the
# valves' own draw makes (followed at once, holding ran away through the supply: more opening,
# more draw, a lower supply)
SUPPLY_FILTER_S = 0.2


def resting(velocity_ref) -> bool:
    """The reference rests: no leg's velocity above RESTING_M_S."""
    return largest_abs(velocity_ref) <= RESTING_M_S


class _Gains:
    """What both forms share: the PID's gains, the valve map and force loop, the velocity
    low-pass (its filter's constants)."""

    def __init__(self, cfg: ControllerConfig, gains: ComputedTorqueGains, n_legs: int, period_s: float):
        w = gains.bandwidth_rad_s
        # per direction (the hexapod's yaw gets its own with the IMU: ComputedTorque)
        self.kp, self.kd = np.full(n_legs, w * w), np.full(n_legs, 2.0 * gains.damping * w)
        self.ki = np.full(n_legs, gains.integral_fraction * w ** 3)
        self.period_s = period_s
        self.velocity_gain = gains.velocity_gain_per_s
        self.hp, self.supply_pa = cfg.hydraulics, cfg.hydraulic_model.supply_pressure_pa
        # the map (and the force rate's floor, a flow through the valve) at the configured supply
        self.forces, self.velocities, self.spool, self.pressure_a, self.pressure_b = cfg.valve_map.at_supply(
            self.supply_pa)
        _, flow_factor = hy.supply_similarity(self.supply_pa, cfg.valve_map.supply_pressure_pa)
        self.force_bandwidth = gains.force_bandwidth_rad_s
        rest = gains.force_bandwidth_rest_rad_s
        self.force_bandwidth_rest = self.force_bandwidth if math.isnan(rest) else rest
        self.force_bandwidth_now = self.force_bandwidth_rest
        self.moving = 0.0                         # the schedule: 1 moving, 0 resting, blended
        self.at_rest = True                       # the reference rested at the last `schedule`
        self.bandwidth_alpha = 1.0 - math.exp(-period_s / FORCE_SCHEDULE_S)
        self.rate_floor = cfg.computed_torque.force_rate_floor * flow_factor
        self.u_max = cfg.limits.spool_max
        self.filter_wn, self.filter_zeta = 2 * math.pi * gains.velocity_filter_hz, FILTER_ZETA
        self.filter_ad, self.filter_bd = second_order_filter(period_s, gains.velocity_filter_hz, FILTER_ZETA)
        self.supply_ratio = np.ones(n_legs)       # each valve's supply over the map's (measured)
        self.supply_alpha = 1.0 - math.exp(-period_s / SUPPLY_FILTER_S)
        self.stiffness = np.zeros(n_legs)         # each leg's oil column at its operating point, N/m
        self.force_gain = np.zeros(n_legs)        # ... and its force loop's gain, spool fraction per N

    def supply_from(self, supply_pa) -> None:
        """Each valve's supply (its P-port transducer's latest sample) against the map's,
        low-passed over SUPPLY_FILTER_S; a reading below a tenth of it (a dead transducer) as
        the configured supply."""
        supply_ratio_into(supply_pa, self.supply_pa, self.supply_alpha, self.supply_ratio)

    def schedule(self, velocity_ref) -> None:
        """The schedule moves toward 1 while the reference moves and toward 0 while it rests
        (`at_rest`), over FORCE_SCHEDULE_S; the force loops' bandwidth between the resting and
        the moving one."""
        self.at_rest = resting(velocity_ref)
        self.moving += self.bandwidth_alpha * ((0.0 if self.at_rest else 1.0) - self.moving)
        rest = self.force_bandwidth_rest
        self.force_bandwidth_now = rest + self.moving * (self.force_bandwidth - rest)

    def spool_commands(self, force_map, force_cmd, force_ref, force_ref_prev, force_measured, velocity_ref,
                       joint_error, strokes_ref) -> bool:
        """`spool_commands_into` with this controller's map, gains and scratch (the force loops'
        bandwidth as `schedule` last set it): writes spool_cmd."""
        return spool_commands_into(force_map, force_cmd, force_ref, force_ref_prev, force_measured, velocity_ref,
                                   joint_error, strokes_ref, self.period_s, self.velocity_gain,
                                   self.force_bandwidth_now,
                                   self.rate_floor,
                                   self.forces, self.velocities, self.spool, self.pressure_a, self.pressure_b,
                                   self.hp, self.supply_pa, self.supply_ratio, self.u_max, self.stiffness,
                                   self.force_gain, self.spool_cmd)


YAW = 5                               # the twist's and pose error's rotation about the base's vertical
# valves at their limit: the others' forces are chosen for the platform's acceleration error,
# a rotation's counted as a translation's at this lever (the rotations are what the legs
# barely see and what the platform's light inertia lets swing), the limited legs' pinned
ROTATION_LEVER_M = 1.0
PIN = 1e6                             # the limited legs' pin, relative to the largest normal-equation term


@njit(cache=True)
def keep_limited_into(limited, u_max, out) -> None:
    """The valves that were at their limit stay there."""
    for i in range(out.shape[0]):
        if abs(limited[i]) >= u_max:
            out[i] = limited[i]


class ComputedTorque(_Gains):
    """The controller's state and scratch arrays; `update(...)` writes the valve inputs.
    `yaw`: the platform's yaw from the IMU beside the legs (None: the legs alone), updated by
    the rig's estimate before each update."""

    def __init__(self, cfg: ControllerConfig, geometry: Geometry, period_s: float, yaw: YawFusion | None = None,
                 capacity=None):
        """`capacity`: the legs' `supervision.capacity.LegCapacity` (their force range over
        velocity, valve fully open, at the configured supply); None: only a saturated valve
        stops the integral."""
        super().__init__(cfg, cfg.computed_torque.hexapod_at(period_s), N_LEGS, period_s)
        self.yaw = yaw
        self.windup_share = cfg.computed_torque.windup_share
        self.ranges = capacity is not None
        self.range_grid, self.range_push, self.range_pull = (
            (capacity.velocities_m_s, capacity.push_n, capacity.pull_n) if self.ranges else (None, None, None))
        w, zeta = cfg.computed_torque.yaw_gains(period_s)
        # with a valid IMU yaw: the yaw's own proportional and derivative gains
        self.kp_imu, self.kd_imu = self.kp.copy(), self.kd.copy()
        self.kp_imu[YAW], self.kd_imu[YAW] = w * w, 2.0 * zeta * w
        self.fused_pose = np.zeros(7)         # the measured pose with the fused yaw
        self.dynamics = InverseDynamics(geometry)
        self.error = np.zeros(6)              # pose error: m, rad
        self.integral = np.zeros(6)
        self.twist_raw = np.zeros(6)          # measured, from the legs' positions' backward differences
        self.twist = np.zeros(6)              # ... low-passed: the encoders' counts make it jump
        self.twist_moving = np.zeros(6)       # ... through the moving low-pass and the resting one,
        self.twist_resting = np.zeros(6)      # blended by the schedule (the counts buzz the valves at rest)
        self.twist_rest_filter_state = np.zeros((6, 3))
        gains = cfg.computed_torque.hexapod
        rest_hz = gains.velocity_filter_rest_hz
        rest_hz = gains.velocity_filter_hz if math.isnan(rest_hz) else rest_hz
        self.rest_filter_wn = 2 * math.pi * rest_hz
        self.rest_filter_ad, self.rest_filter_bd = second_order_filter(period_s, rest_hz, FILTER_ZETA)
        self.position_prev = np.zeros(N_LEGS)     # the legs' positions the cycle before, m
        self.position_rate = np.zeros(N_LEGS)     # ... and their backward difference, m/s
        self.twist_filter_state = np.zeros((6, 3))
        self.accel_cmd = np.zeros(6)
        self.force_cmd = self.dynamics.force_n
        self.force_ref_prev = np.zeros(N_LEGS)
        self.spool_cmd = np.zeros(N_LEGS)
        self.stiff_gain = cfg.computed_torque.stiff_integral_per_s2
        self.velocity_error = np.zeros(N_LEGS)        # the legs' error with the stiff integral's share
        # where the velocity's share of the stiff integral counts from: the integral, followed
        # once the reference has rested a while (the last move's seal lag is no guide to the next's)
        self.stiff_origin = np.zeros(STIFF_COUNT)
        self.rest_cycles = 0
        self.rest_hold_cycles = round(cfg.computed_torque.stiff_rest_hold_s / period_s)
        unwind_s = cfg.computed_torque.stiff_rest_unwind_s
        self.stiff_rest_alpha = 1.0 - math.exp(-period_s / unwind_s) if unwind_s > 0.0 else 0.0
        self._lu = np.empty((6, 6))
        self._fresh = True                    # no previous reference force yet
        # the allocation's weights: the platform's inertia at home (the declared payload), per direction
        self.dynamics.task_space_terms(np.asarray(geometry.home_position_m, float), np.array([1.0, 0.0, 0.0, 0.0]),
                                       np.zeros(6))
        lever = np.array([1.0, 1.0, 1.0, ROTATION_LEVER_M, ROTATION_LEVER_M, ROTATION_LEVER_M])
        self.allocation_weights = (lever / np.diag(self.dynamics.mass_matrix)) ** 2
        self.force_alloc = np.zeros(N_LEGS)
        self.spool_limited = np.zeros(N_LEGS)
        self._wrench, self._rhs, self._normal = np.zeros(6), np.zeros(N_LEGS), np.zeros((N_LEGS, N_LEGS))
        # load the allocation's kernels now (configure), not in the first saturated cycle
        reallocate_into(self.dynamics.jacobian, self.force_alloc, self.force_alloc, self.spool_limited, self.u_max,
                        self.allocation_weights, PIN, self._wrench, self._normal, self._rhs, self._lu, self.force_alloc)
        keep_limited_into(self.spool_limited, self.u_max, self.spool_limited)

    def reset(self) -> None:
        """Valves locked or a fault: the integral and the reference-force history start again."""
        self.integral.fill(0.0)
        self.stiff_origin.fill(0.0)
        self.rest_cycles = 0
        self.twist_filter_state.fill(0.0)
        self.twist_rest_filter_state.fill(0.0)
        self._fresh = True

    def update(self, platform, strokes_ref, position_m, velocity_estimate, joint_error, velocity_ref, accel_ref,
               force_measured) -> bool:
        """One cycle from the platform model (measured and reference pose, the reference's
        twist, acceleration and forces: the legs' `accel_ref` is not used) and the legs'
        positions (`velocity_estimate`, the Kalman filters', is not used: see
        `backward_difference_into`); writes spool_cmd (fraction of full input). False: singular
        (spool_cmd held)."""
        if self._fresh:
            self.force_ref_prev[:] = platform.force_n
            self.position_prev[:] = position_m
            self._fresh = False
        self.schedule(velocity_ref)
        backward_difference_into(position_m, self.period_s, self.position_prev, self.position_rate)
        pose, ref_pose = platform.dk.pose, platform.ref_dk.pose
        if gauss_solve_into(platform.jacobian, self.position_rate, self._lu, self.twist_raw, False) == 0.0:
            return False
        low_pass_into(self.twist_raw, self.twist_filter_state, self.filter_ad, self.filter_bd, self.filter_wn,
                      self.filter_zeta, self.twist_moving)
        low_pass_into(self.twist_raw, self.twist_rest_filter_state, self.rest_filter_ad, self.rest_filter_bd,
                      self.rest_filter_wn, self.filter_zeta, self.twist_resting)
        blend_into(self.twist_resting, self.twist_moving, self.moving, self.twist)
        kp, kd = self.kp, self.kd
        yaw = self.yaw
        if yaw is not None and yaw.valid:     # the yaw and its rate the IMU's, its own gains
            with_yaw_into(pose, yaw.yaw_rad, self.fused_pose)
            pose_error_into(ref_pose, self.fused_pose, self.error)
            self.twist[YAW] = yaw.rate_rad_s
            kp, kd = self.kp_imu, self.kd_imu
        else:
            pose_error_into(ref_pose, pose, self.error)
        task_acceleration_into(platform.accel, platform.twist, self.twist, self.error, self.integral, kp, kd,
                               self.ki, self.accel_cmd)
        if not self.dynamics.forces(pose[0:3], pose[3:7], self.twist, self.accel_cmd):
            return False
        stiff_velocity_into(platform.jacobian, self.integral, self.stiff_origin, self.stiff_gain, self.velocity_gain,
                            joint_error, self.velocity_error)
        saturated = self.spool_commands(self.force_cmd, self.force_cmd, platform.force_n, self.force_ref_prev,
                                        force_measured, velocity_ref, self.velocity_error, strokes_ref)
        if saturated and reallocate_into(platform.jacobian, self.force_cmd, force_measured, self.spool_cmd, self.u_max,
                                         self.allocation_weights, PIN, self._wrench, self._normal, self._rhs, self._lu,
                                         self.force_alloc):
            # the free legs take over what the limited ones cannot: the rotations first
            self.spool_limited[:] = self.spool_cmd
            self.force_cmd[:] = self.force_alloc
            self.spool_commands(self.force_cmd, self.force_cmd, platform.force_n, self.force_ref_prev,
                                force_measured, velocity_ref, self.velocity_error, strokes_ref)
            keep_limited_into(self.spool_limited, self.u_max, self.spool_cmd)
        self.force_ref_prev[:] = platform.force_n
        # conditional integration (anti-windup): not while a valve saturates or a leg is asked
        # beyond what it can give
        if not saturated and not (self.ranges and beyond_force_range(
                self.force_cmd, velocity_ref, self.supply_ratio, self.range_grid, self.range_push, self.range_pull,
                self.windup_share)):
            integrate_into(self.integral, self.error, self.period_s)
        # the velocity's share fades once the reference has rested rest_hold_cycles (the legs
        # settle onto it first); the kernel runs every cycle (alpha 0: held)
        self.rest_cycles = min(self.rest_cycles + 1, self.rest_hold_cycles) if self.at_rest else 0
        following = self.at_rest and self.rest_cycles >= self.rest_hold_cycles
        stiff_origin_step(self.integral, self.stiff_rest_alpha if following else 0.0, self.stiff_origin)
        return True


LOAD_FILTER_HZ = 1.0                  # the load cell's low-pass: the load's weight, not its dynamics


class LegComputedTorque(_Gains):
    """The same control on one actuator per leg in joint space (the test bench): task-space
    PID on the stroke, the load from its load cell, each valve through the map. Its own
    velocity gain: the test bench's leg is light (its oil-column mode is far above the
    hexapod's horizontal modes), so a stiffer velocity loop stays damped there."""

    def __init__(self, cfg: ControllerConfig, n_legs: int, period_s: float):
        super().__init__(cfg, cfg.computed_torque.testbench, n_legs, period_s)
        self.rod_mass = cfg.actuator.moving_mass_kg
        self.friction = cfg.friction.vector
        self.load_alpha = first_order_gain(period_s, LOAD_FILTER_HZ)
        self.integral = np.zeros(n_legs)
        self.velocity = np.zeros(n_legs)      # the estimate, low-passed
        self._velocity_filter = np.zeros((n_legs, 3))
        self.load_force = np.zeros(n_legs)    # the load cell, low-passed
        self.accel_cmd = np.zeros(n_legs)
        self.force_map = np.zeros(n_legs)
        self.force_cmd = np.zeros(n_legs)
        self.force_ref = np.zeros(n_legs)
        self.force_ref_prev = np.zeros(n_legs)
        self.spool_cmd = np.zeros(n_legs)
        self._fresh = True

    def reset(self) -> None:
        self.integral.fill(0.0)
        self._velocity_filter.fill(0.0)
        self._fresh = True

    def update(self, platform, strokes_ref, position_m, velocity_estimate, joint_error, velocity_ref, accel_ref,
               force_measured) -> bool:
        """One cycle, as `ComputedTorque.update` (no platform: `platform` is not used; the
        velocity the leg's Kalman filter's, `position_m` not used); writes spool_cmd. Always
        True: the stroke has no singularity."""
        self.schedule(velocity_ref)
        if self._fresh:                       # the load's weight and the reference force start here
            self.load_force[:] = force_measured
        first_order_into(force_measured, self.load_alpha, self.load_force)
        low_pass_into(velocity_estimate, self._velocity_filter, self.filter_ad, self.filter_bd, self.filter_wn,
                      self.filter_zeta, self.velocity)
        task_acceleration_into(accel_ref, velocity_ref, self.velocity, joint_error, self.integral, self.kp,
                               self.kd, self.ki, self.accel_cmd)
        leg_forces_into(self.accel_cmd, accel_ref, self.load_force, force_measured, velocity_ref, joint_error,
                        self.velocity_gain, self.rod_mass, self.friction, self.force_map, self.force_cmd,
                        self.force_ref)
        if self._fresh:
            self.force_ref_prev[:] = self.force_ref
            self._fresh = False
        saturated = self.spool_commands(self.force_map, self.force_cmd, self.force_ref, self.force_ref_prev,
                                        force_measured, velocity_ref, joint_error, strokes_ref)
        self.force_ref_prev[:] = self.force_ref
        if not saturated:
            integrate_into(self.integral, joint_error, self.period_s)
        return True
