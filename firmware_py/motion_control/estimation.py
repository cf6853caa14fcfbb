"""Per-leg state estimation (thesis chapter 7.5.2-7.5.6), numba kernels writing in place.

- Adaptive Kalman filter (eq. 7.41-7.50): position, velocity and acceleration of the
  piston from the quantised encoder, white-jerk process model.
- LuGre friction observer (eq. 7.30-7.32).
- Load mass by recursive least squares with exponential forgetting (eq. 7.33-7.37), on
  signals filtered by a 2nd-order low-pass F(s).
- Load pressure from the load cell (eq. 7.38-7.39) with a filtered differentiator.

Deviations from the thesis, derived from free-body diagrams (the thesis's own eq.
7.33-7.35 cannot all hold: adding 7.33 and 7.34 does not give 7.35, and 7.34 has the
friction and the load on the wrong side of the load cell):
  load (mass m_L, above the load cell):  m_L (y'' + g_ax) = F_s - F_load_friction
  piston and rod (mass m_p):             m_p (y'' + g_ax) = A_p P_L - F_f - F_s
with F_s the load-cell force (+ = the rod pushes the load), F_f the cylinder's seal
friction, P_L = p_A - alpha p_B and g_ax the gravity component along the actuator axis
(g on the vertical test bench). Hence
  mass regression (replaces 7.35-7.37):  m_L F(s)[s^2 y + g_ax] = F(s) F_s
  load pressure (replaces 7.38-7.39):    P_L = (F_s + F_f + m_p (y'' + g_ax)) / A_p
  piston inverse dynamics (7.40):        P_Lr = ((m_p + m_L)(y_r'' + g_ax) + F_f) / A_p
The guide's friction acts on the load side and is an unmodelled disturbance of the mass
estimate (Table D.1: about 11-13 N at rest), as the cylinder's friction is in the thesis.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from physics.lugre import bristle_coefficients, stribeck

# -- adaptive Kalman filter (eq. 7.41-7.50) -------------------------------------------------

def kalman_model(period_s: float, jerk_psd: float) -> tuple[np.ndarray, np.ndarray]:
    """A (eq. 7.46) and Q (eq. 7.48) of the white-jerk model for one sample period.

    Q is the exact discretisation of a white jerk of PSD q; the thesis prints T^3/6 in
    the middle of eq. 7.48 where the discretisation gives T^3/3 (its Q would not be
    positive definite), so T^3/3 is used.
    """
    t = period_s
    a = np.array([[1.0, t, t * t / 2.0], [0.0, 1.0, t], [0.0, 0.0, 1.0]])
    q = jerk_psd * np.array([[t ** 5 / 20.0, t ** 4 / 8.0, t ** 3 / 6.0],
                             [t ** 4 / 8.0, t ** 3 / 3.0, t ** 2 / 2.0],
                             [t ** 3 / 6.0, t ** 2 / 2.0, t]])
    return a, q


def quantisation_variance(resolution_m: float) -> float:
    """R of the encoder: a uniform quantisation error of one count has variance res^2 / 12.

    (eq. 7.49 is garbled in the thesis's text; this is the standard value it stands for.)
    """
    return resolution_m * resolution_m / 12.0


@njit(cache=True)
def adaptive_r(r_base, gain, velocity, velocity_ref):
    """eq. 7.50: R_a,k = gain R / (1 + v_{k-1}^2), v in units of velocity_ref (the thesis: mm/s)."""
    v = velocity / velocity_ref
    return gain * r_base / (1.0 + v * v)


@njit(cache=True)
def kalman_step_into(x, p, a, q, z, has_z, r, xp, pp):
    """One predict (eq. 7.41-7.42) and, when a measurement came, update (eq. 7.43-7.45).

    x (3,), p (3, 3) updated in place; xp (3,), pp (3, 3) scratch. H = [1, 0, 0] (eq. 7.47).
    """
    for i in range(3):
        s = 0.0
        for j in range(3):
            s += a[i, j] * x[j]
        xp[i] = s
    for i in range(3):                       # pp = A P A^T + Q
        for j in range(3):
            s = 0.0
            for k in range(3):
                ak = a[i, k]
                if ak != 0.0:
                    for m in range(3):
                        s += ak * p[k, m] * a[j, m]
            pp[i, j] = s + q[i, j]
    if not has_z:
        for i in range(3):
            x[i] = xp[i]
            for j in range(3):
                p[i, j] = pp[i, j]
        return
    innovation_var = pp[0, 0] + r
    innovation = z - xp[0]
    for i in range(3):
        gain = pp[i, 0] / innovation_var      # K = P- H^T / (H P- H^T + R)
        x[i] = xp[i] + gain * innovation
        for j in range(3):
            p[i, j] = pp[i, j] - gain * pp[0, j]     # P = (I - K H) P-


# -- LuGre friction observer (eq. 7.30-7.32) ------------------------------------------------

@njit(cache=True)
def lugre_observer_step(fp, gain_k, z_state, leg, velocity, position_error, period_s):
    """Advance the bristle state z_state[leg] one period and return the friction estimate.

    eq. 7.30 z' = v - sigma0 |v| / g(v) z - k e, eq. 7.31 g(v) (eq. 6.3, physics.lugre),
    eq. 7.32 Ff = sigma0 z + sigma1 z' + sigma2 v, `fp` the LuGre vector of physics.lugre.
    The bristle dynamics are stiff (sigma0/g ~ 1e4 1/m): z is advanced by implicit Euler,
    stable for any |v| and period.
    """
    v = velocity
    g, sigma2 = stribeck(v, fp)
    g = abs(g)
    z = z_state[leg]
    sigma0, sigma1 = bristle_coefficients(z, fp)
    rate = sigma0 * abs(v) / max(g, 1e-9)
    drive = v - gain_k * position_error
    z = (z + period_s * drive) / (1.0 + period_s * rate)
    z_dot = drive - rate * z
    z_state[leg] = z
    return sigma0 * z + sigma1 * z_dot + sigma2 * v


# -- filters -----------------------------------------------------------------------------

def first_order_gain(period_s: float, corner_hz: float) -> float:
    """a of the discrete first-order low-pass y += a (u - y), its step response matched at
    the samples: a = 1 - exp(-2 pi f T)."""
    return 1.0 - math.exp(-2.0 * math.pi * corner_hz * period_s)


def second_order_filter(period_s: float, natural_hz: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of F(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2).

    State [x, x']; returns (Ad (2, 2), Bd (2,)), so x_{k+1} = Ad x_k + Bd u_k.
    """
    # configure time only: the hosts that import this module never load scipy.linalg
    from scipy.linalg import expm

    wn = 2.0 * math.pi * natural_hz
    a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
    big = np.zeros((3, 3))
    big[:2, :2] = a * period_s
    big[1, 2] = wn * wn * period_s
    phi = expm(big)
    return np.ascontiguousarray(phi[:2, :2]), np.ascontiguousarray(phi[:2, 2])


@njit(cache=True)
def filter_step(state, ad, bd, wn, zeta, u):
    """One sample of F(s): returns s^2 F(s) u at this sample, then advances the state.

    state = [x, x', u_prev]: F(s) u is state[0], s F(s) u is state[1]. With the input held
    between samples x'' jumps by wn^2 (u_k - u_{k-1}) at each sample, so the value
    returned is the mean of its two one-sided limits:
    s^2 F(s) u = wn^2 ((u_k + u_{k-1}) / 2 - x) - 2 zeta wn x' (no numerical differentiation).
    """
    x, xd = state[0], state[1]
    second = wn * wn * (0.5 * (u + state[2]) - x) - 2.0 * zeta * wn * xd
    state[0] = ad[0, 0] * x + ad[0, 1] * xd + bd[0] * u
    state[1] = ad[1, 0] * x + ad[1, 1] * xd + bd[1] * u
    state[2] = u
    return second


# -- load mass (eq. 7.33-7.37, corrected) ---------------------------------------------------

@njit(cache=True)
def rls_step(theta, p, leg, phi, psi, forgetting, p_max, theta_max):
    """Scalar RLS with exponential forgetting: psi = theta phi + noise.

    K = P phi / (lambda + phi^2 P), theta += K (psi - phi theta), P = (P - K phi P) / lambda;
    P is capped (no blow-up while phi carries no information) and theta kept in [0, max].
    """
    pk = p[leg]
    gain = pk * phi / (forgetting + phi * phi * pk)
    estimate = theta[leg] + gain * (psi - phi * theta[leg])
    theta[leg] = min(max(estimate, 0.0), theta_max)
    p[leg] = min((pk - gain * phi * pk) / forgetting, p_max)
    return theta[leg]


# -- load pressure and piston inverse dynamics ----------------------------------------------

@njit(cache=True)
def load_pressure(force_n, friction_n, moving_mass_kg, accel, gravity_axial, area_m2):
    """P_L = (F_s + F_f + m_p (y'' + g_ax)) / A_p (eq. 7.38-7.39 as derived in the module doc)."""
    return (force_n + friction_n + moving_mass_kg * (accel + gravity_axial)) / area_m2


@njit(cache=True)
def piston_inverse_dynamics(total_mass_kg, accel_ref, gravity_axial, friction_n, area_m2):
    """P_Lr = ((m_p + m_L)(y_r'' + g_ax) + F_f) / A_p (eq. 7.40 with the signs of eq. 7.33)."""
    return (total_mass_kg * (accel_ref + gravity_axial) + friction_n) / area_m2
