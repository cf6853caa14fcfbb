"""Joint-space control of the servo-hydraulic actuators (thesis chapters 7.4, 7.5, 11.4).

Three controllers share one per-leg pipeline (`legs_update`, a numba kernel over the legs
that allocates nothing):

1. estimation: adaptive Kalman filter (eq. 7.41-7.50), LuGre observer (eq. 7.30-7.32),
   load mass by RLS (eq. 7.33-7.37), load pressure (eq. 7.38-7.39) - see estimation.py;
2. control law, u in volts of the valve input:
   - PI (chapter 7.4):             u = Kp e + Ki int(e)
   - adaptive PI+P (eq. 7.28-7.29): u = Cpl (P_Lr - P_L) + Cp(y, m) e + Ci(y, m) int(e),
     P_Lr from the piston's inverse dynamics (eq. 7.40), Cp, Ci from Table 7.2
   - model-based (eq. 11.5):       the same with P_Lr = (tau_i + F_f) / A_p, tau_i the
     virtual-work inverse dynamics of the platform along the reference;
   e = y_r - y; the integrator is frozen while the driver saturates in the direction of
   the error (conditional-integration anti-windup, Fig. 7.5).

Gain schedule (chapter 7.5.1.2): natural cubic splines along the position for each load
column of Table 7.2, then the quadratic through the three loads: C2 in position, smooth in
load, exact at the table's nodes; clamped at the table's edges.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.config import ControllerConfig
from firmware_py.motion_control.estimation import (
    adaptive_r,
    filter_step,
    kalman_model,
    kalman_step_into,
    load_pressure,
    lugre_observer_step,
    piston_inverse_dynamics,
    quantisation_variance,
    rls_step,
    second_order_filter,
)
from physics.constants import GRAVITY_M_S2
from protocol.enums import ControllerKind

PI, ADAPTIVE, MODEL_BASED = int(ControllerKind.PI), int(ControllerKind.ADAPTIVE), int(ControllerKind.MODEL_BASED)
COMPUTED_TORQUE = int(ControllerKind.COMPUTED_TORQUE)      # the hexapod's, computed_torque.py
# command-line names of the controllers, from CTRL_STATUS.CONTROLLER's value table
CONTROLLER_NAMES = {kind.name.lower().replace("_", "-"): int(kind) for kind in ControllerKind}

# -- gain schedule ---------------------------------------------------------------------------


def spline_coefficients(positions: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(n_loads, n_intervals, 4) polynomial coefficients [c0, c1, c2, c3] of natural cubic
    splines through each row of `table`: value = c0 + c1 d + c2 d^2 + c3 d^3, d = y - y_i."""
    # imported at configure time only: the hosts that import this module never load it
    from scipy.interpolate import CubicSpline
    out = np.empty((table.shape[0], len(positions) - 1, 4))
    for j, row in enumerate(table):
        c = CubicSpline(positions, row, bc_type="natural").c        # (4, n_int), highest power first
        out[j] = c[::-1].T
    return out


@njit(cache=True)
def schedule_eval(breaks, coef, loads, position, load):
    """Gain at (position, load): cubic spline in position per load, quadratic in load."""
    n = breaks.shape[0]
    y = min(max(position, breaks[0]), breaks[n - 1])
    i = 0
    while i < n - 2 and y >= breaks[i + 1]:
        i += 1
    d = y - breaks[i]
    m = min(max(load, loads[0]), loads[2])
    m0, m1, m2 = loads[0], loads[1], loads[2]
    l0 = (m - m1) * (m - m2) / ((m0 - m1) * (m0 - m2))
    l1 = (m - m0) * (m - m2) / ((m1 - m0) * (m1 - m2))
    l2 = (m - m0) * (m - m1) / ((m2 - m0) * (m2 - m1))
    value = 0.0
    for j, weight in ((0, l0), (1, l1), (2, l2)):
        c = coef[j, i]
        value += weight * (c[0] + d * (c[1] + d * (c[2] + d * c[3])))
    return value


# -- control law -----------------------------------------------------------------------------

@njit(cache=True)
def pi_antiwindup(error, integral, leg, kp, ki, extra, period_s, u_max):
    """u = extra + Kp e + Ki I, saturated at +/-u_max; I integrates e unless the output is
    saturated and e pushes further into the saturation (Fig. 7.5). Updates integral[leg]."""
    u = extra + kp * error + ki * integral[leg]
    if not (abs(u) >= u_max and error * u > 0.0):
        integral[leg] += error * period_s
    return min(max(u, -u_max), u_max)


@njit(cache=True)
def filtered_derivative(state, y, alpha, period_s):
    """The D term's dy/dt: the backward difference through a first-order low-pass
    (pole alpha = exp(-2 pi f T)); state = [derivative, previous y], updated in place."""
    state[0] = alpha * state[0] + (1.0 - alpha) * (y - state[1]) / period_s
    state[1] = y
    return state[0]


# -- the per-leg pipeline --------------------------------------------------------------------

# parameter vector
(JP_T, JP_R_BASE, JP_R_GAIN, JP_V_REF, JP_LAMBDA, JP_P_MAX, JP_M_MAX, JP_RLS_WN, JP_RLS_ZETA,
 JP_D_WN, JP_D_ZETA, JP_KI_SCALE, JP_MASS_OFFSET, JP_PI_KP, JP_PI_KI, JP_KPL, JP_U_MAX,
 JP_MOVING_MASS, JP_AREA, JP_FF_SCALE, JP_KP_SCALE, JP_OBSERVER_K, JP_PI_KD, JP_DY_ALPHA, JP_GUIDE_FC, JP_GUIDE_FV,
 JP_SIZE) = range(27)
# below this speed the guide is taken as sticking, its force unknown and none taken off: a leg
# settling after a step creeps below it in the Kalman estimate while the slide is stuck
GUIDE_STICK_M_S = 5e-3
# state and outputs per leg
# (each 2nd-order filter keeps 3 columns: F u, s F u, the previous input)
# (the D term keeps 2: its filtered dy/dt, the previous y)
(ST_Z, ST_MASS, ST_RLS_P, ST_INTEGRAL, ST_ACCEL_D, ST_FRICTION, ST_PL, ST_PLR, ST_KP, ST_KI, ST_ERROR, ST_U,
 ST_FY, ST_FF, ST_FG, ST_D, ST_DY, ST_SIZE) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 15, 18, 21, 24, 26)


@njit(cache=True)
def legs_update(mode, jp, position, fresh_legs, force_n, yr, ar, g_axial, tau_n, active, st, kx, kp_mat, a, q,
                xp, pp, fp, rls_ad, rls_bd, d_ad, d_bd, breaks, kp_coef, ki_coef, loads):
    """Estimation and control of every leg for one cycle, from the measurements (position,
    fresh, force), the reference (yr, ar), gravity along each leg and the model-based
    actuator forces; writes st[:, ST_U] (volts) and the other ST_ columns."""
    period = jp[JP_T]
    for leg in range(position.shape[0]):
        x = kx[leg]
        p = kp_mat[leg]
        fresh = fresh_legs[leg]
        r = adaptive_r(jp[JP_R_BASE], jp[JP_R_GAIN], x[1], jp[JP_V_REF])              # eq. 7.50
        kalman_step_into(x, p, a, q, position[leg], fresh, r, xp, pp)                 # eq. 7.41-7.45
        y = position[leg] if fresh else x[0]
        error = yr[leg] - y
        g_ax = g_axial[leg]
        force = force_n[leg]
        friction = lugre_observer_step(fp, jp[JP_OBSERVER_K], st[leg], ST_Z, x[1], error, period)   # eq. 7.30-7.32
        accel_d = filter_step(st[leg, ST_D:ST_D + 3], d_ad, d_bd, jp[JP_D_WN], jp[JP_D_ZETA], y)
        dy = filtered_derivative(st[leg, ST_DY:ST_DY + 2], y, jp[JP_DY_ALPHA], period)
        # eq. 7.37 (corrected): m_L F(s)[s^2 y + g_ax] = F(s) F_s
        phi = filter_step(st[leg, ST_FY:ST_FY + 3], rls_ad, rls_bd, jp[JP_RLS_WN], jp[JP_RLS_ZETA], y)
        phi += st[leg, ST_FG]
        filter_step(st[leg, ST_FG:ST_FG + 3], rls_ad, rls_bd, jp[JP_RLS_WN], jp[JP_RLS_ZETA], g_ax)
        psi = st[leg, ST_FF]
        # the load cell carries the slide's guide friction too (test bench): taken off while it
        # slides, its identified Fc sign(v) + sigma_v v (Table D.1), as eq. 7.36 takes off Ff
        v = x[1]
        guide = (jp[JP_GUIDE_FC] * (1.0 if v > 0.0 else -1.0) + jp[JP_GUIDE_FV] * v) if abs(v) > GUIDE_STICK_M_S \
            else 0.0
        filter_step(st[leg, ST_FF:ST_FF + 3], rls_ad, rls_bd, jp[JP_RLS_WN], jp[JP_RLS_ZETA], force - guide)
        mass = st[leg, ST_MASS]
        if fresh:
            mass = rls_step(st[:, ST_MASS], st[:, ST_RLS_P], leg, phi, psi, jp[JP_LAMBDA], jp[JP_P_MAX],
                            jp[JP_M_MAX])
        pl = load_pressure(force, friction, jp[JP_MOVING_MASS], accel_d, g_ax, jp[JP_AREA])   # eq. 7.39
        if mode == MODEL_BASED:                                                                 # eq. 11.5
            plr = (jp[JP_FF_SCALE] * tau_n[leg] + friction) / jp[JP_AREA]
        else:                                                                                   # eq. 7.40
            plr = piston_inverse_dynamics(jp[JP_MOVING_MASS] + mass, ar[leg], g_ax, friction, jp[JP_AREA])
        if mode == PI:
            kp, ki, extra = jp[JP_PI_KP], jp[JP_PI_KI], -jp[JP_PI_KD] * dy      # D on the measurement
        else:                                                                                   # eq. 7.29
            load = mass - jp[JP_MASS_OFFSET]
            kp = jp[JP_KP_SCALE] * schedule_eval(breaks, kp_coef, loads, y, load)
            ki = jp[JP_KI_SCALE] * schedule_eval(breaks, ki_coef, loads, y, load)
            extra = jp[JP_KPL] * (plr - pl)
        if active:
            u = pi_antiwindup(error, st[:, ST_INTEGRAL], leg, kp, ki, extra, period, jp[JP_U_MAX])
        else:
            st[leg, ST_INTEGRAL] = 0.0
            u = 0.0
        st[leg, ST_ACCEL_D] = accel_d
        st[leg, ST_FRICTION] = friction
        st[leg, ST_PL] = pl
        st[leg, ST_PLR] = plr
        st[leg, ST_KP] = kp
        st[leg, ST_KI] = ki
        st[leg, ST_ERROR] = error
        st[leg, ST_U] = u


class JointController:
    """Every array of the per-leg pipeline, allocated once; `update(...)` runs one cycle.

    Outputs: `u_v` (the valve input per leg, V), `error_m` (tracking error), `kalman_x`
    (position, velocity, acceleration per leg) and the other ST_* columns of `st`.
    """

    def __init__(self, cfg: ControllerConfig, n_legs: int, period_s: float, *, moving_mass_kg: float,
                 mass_offset_kg: float, initial_position_m: float = 0.0, kp_factor: float = 1.0,
                 ki_factor: float = 1.0, guide_friction: tuple[float, float] = (0.0, 0.0)):
        self.cfg, self.n_legs, self.period_s = cfg, n_legs, period_s
        self.mode = PI
        jp = np.zeros(JP_SIZE)
        jp[JP_T] = period_s
        jp[JP_R_BASE] = quantisation_variance(cfg.actuator.encoder_resolution_m)
        jp[JP_R_GAIN] = cfg.kalman.adaptive_gain
        jp[JP_V_REF] = cfg.kalman.adaptive_velocity_ref_m_s
        jp[JP_LAMBDA] = cfg.mass_estimator.forgetting
        jp[JP_P_MAX] = cfg.mass_estimator.covariance_max
        jp[JP_M_MAX] = cfg.mass_estimator.mass_max_kg
        jp[JP_RLS_WN] = 2 * math.pi * cfg.mass_estimator.filter_hz
        jp[JP_RLS_ZETA] = cfg.mass_estimator.filter_zeta
        jp[JP_D_WN] = 2 * math.pi * cfg.load_pressure.differentiator_hz
        jp[JP_D_ZETA] = cfg.load_pressure.differentiator_zeta
        jp[JP_KI_SCALE] = cfg.adaptive.ki_scale * ki_factor
        jp[JP_MASS_OFFSET] = mass_offset_kg
        jp[JP_KP_SCALE] = kp_factor
        jp[JP_PI_KP] = cfg.pi.kp_v_m * kp_factor
        jp[JP_PI_KI] = cfg.pi.ki_v_m_s * ki_factor
        jp[JP_PI_KD] = cfg.pi.kd_v_s_m * kp_factor
        jp[JP_DY_ALPHA] = math.exp(-2.0 * math.pi * cfg.pi.derivative_filter_hz * period_s)
        jp[JP_KPL] = cfg.adaptive.kpl_v_pa
        jp[JP_U_MAX] = cfg.pi.saturation_v * cfg.limits.spool_max
        jp[JP_MOVING_MASS] = moving_mass_kg
        jp[JP_AREA] = cfg.actuator.piston_area_m2
        jp[JP_FF_SCALE] = cfg.model_based.feedforward_scale
        jp[JP_OBSERVER_K] = cfg.friction.observer_gain_per_s
        jp[JP_GUIDE_FC], jp[JP_GUIDE_FV] = guide_friction       # N, N s/m: between the rod and the load
        self.jp = jp
        self.a, self.q = kalman_model(period_s, cfg.kalman.jerk_psd_m2_s5)
        rls, lp = cfg.mass_estimator, cfg.load_pressure
        self.rls_ad, self.rls_bd = second_order_filter(period_s, rls.filter_hz, rls.filter_zeta)
        self.d_ad, self.d_bd = second_order_filter(period_s, lp.differentiator_hz, lp.differentiator_zeta)
        self.breaks = np.ascontiguousarray(cfg.adaptive.table_position_m)
        self.loads = np.ascontiguousarray(cfg.adaptive.table_load_kg)
        self.kp_coef = spline_coefficients(self.breaks, cfg.adaptive.table_kp)
        self.ki_coef = spline_coefficients(self.breaks, cfg.adaptive.table_ki)
        self.friction = cfg.friction.vector
        self.st = np.zeros((n_legs, ST_SIZE))
        self.u_v = self.st[:, ST_U]                   # views, made once
        self.error_m = self.st[:, ST_ERROR]
        self.mass_kg = self.st[:, ST_MASS]
        self.load_pressure_pa = self.st[:, ST_PL]
        self.friction_n = self.st[:, ST_FRICTION]
        self.integral = self.st[:, ST_INTEGRAL]
        self.kalman_x = np.zeros((n_legs, 3))
        self.kalman_p = np.zeros((n_legs, 3, 3))
        self.position_estimate = self.kalman_x[:, 0]
        self.velocity_estimate = self.kalman_x[:, 1]
        self.acceleration_estimate = self.kalman_x[:, 2]
        # the position each leg's laws read this cycle: the encoder's, or the filter's prediction
        # for a leg whose sample is late (the D term's previous input, written every cycle)
        self.position_read = self.st[:, ST_DY + 1]
        self._xp = np.zeros(3)
        self._pp = np.zeros((3, 3))
        self.reset(initial_position_m)

    def reset(self, position_m=0.0, gravity_axial=None) -> None:
        """Estimators at rest at `position_m` (scalar or per leg), mass at its initial value."""
        cfg = self.cfg
        g = np.broadcast_to(GRAVITY_M_S2 if gravity_axial is None else gravity_axial, (self.n_legs,))
        self.kalman_x.fill(0.0)
        self.kalman_x[:, 0] = position_m
        self.kalman_p[:] = np.diag([self.jp[JP_R_BASE], 1e-4, 1e-2])
        self.st.fill(0.0)
        self.st[:, ST_MASS] = cfg.mass_estimator.initial_kg
        self.st[:, ST_RLS_P] = cfg.mass_estimator.covariance_initial
        for column, value in ((ST_FY, self.kalman_x[:, 0]), (ST_D, self.kalman_x[:, 0]), (ST_FG, g),
                              (ST_FF, cfg.mass_estimator.initial_kg * g)):
            self.st[:, column] = value          # F u
            self.st[:, column + 2] = value      # previous input: at rest
        self.st[:, ST_DY + 1] = self.kalman_x[:, 0]

    def restart_at(self, position_m, gravity_axial=None) -> None:
        """As `reset`, but the load's mass estimate (RLS) and its covariance are kept: after a
        fault the load is the same, only the motion states start again at the measurement."""
        mass, covariance = self.st[:, ST_MASS].copy(), self.st[:, ST_RLS_P].copy()
        self.reset(position_m, gravity_axial)
        self.st[:, ST_MASS] = mass
        self.st[:, ST_RLS_P] = covariance

    def set_mode(self, mode: int) -> None:
        """Switch controller; the integral carries over (bumpless for equal gains)."""
        self.mode = int(mode)

    def update(self, position_m, fresh, force_n, yr, ar, g_axial, tau_n, active: bool) -> None:
        """One cycle of every leg; `tau_n` is read by the model-based controller only."""
        legs_update(self.mode, self.jp, position_m, fresh, force_n, yr, ar, g_axial, tau_n, active, self.st,
                    self.kalman_x, self.kalman_p, self.a, self.q, self._xp, self._pp, self.friction, self.rls_ad,
                    self.rls_bd, self.d_ad, self.d_bd, self.breaks, self.kp_coef, self.ki_coef, self.loads)
