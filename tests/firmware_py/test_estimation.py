"""Estimators of chapter 7.5 against their equations and against library oracles
(filterpy's KalmanFilter, SciPy's lsim)."""

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy import signal

from firmware_py.config import load_config
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

T = 0.002


def quantised_motion(n=3000, resolution=0.125e-3, seed=3):
    t = np.arange(n) * T
    y = 0.15 + 0.05 * np.sin(2.0 * t) + 0.01 * np.sin(9.0 * t)
    rng = np.random.default_rng(seed)
    measured = np.round((y + 2e-5 * rng.standard_normal(n)) / resolution) * resolution
    return t, y, measured


def test_kalman_equals_filterpy_step_by_step():
    """eq. 7.41-7.45 with the adaptive R of eq. 7.50 applied to both filters."""
    a, q = kalman_model(T, 50.0)
    r_base = quantisation_variance(0.125e-3)
    _, _, z = quantised_motion()
    x = np.array([z[0], 0.0, 0.0])
    p = np.diag([r_base, 1e-4, 1e-2])
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.x = x.copy().reshape(3, 1)
    kf.P = p.copy()
    kf.F, kf.Q, kf.H = a, q, np.array([[1.0, 0.0, 0.0]])
    xp, pp = np.zeros(3), np.zeros((3, 3))
    worst = 0.0
    for k, zk in enumerate(z):
        has_z = k % 97 != 5                       # a missing frame now and then: predict only
        r = adaptive_r(r_base, 10.0, x[1], 1e-3)
        kf.R = np.array([[10.0 * r_base / (1.0 + (kf.x[1, 0] / 1e-3) ** 2)]])
        kalman_step_into(x, p, a, q, zk, has_z, r, xp, pp)
        kf.predict()
        if has_z:
            kf.update(np.array([[zk]]))
        worst = max(worst, np.max(np.abs(x - kf.x[:, 0]) / np.array([1e-6, 1e-4, 1e-2])))
        np.testing.assert_allclose(p, kf.P, rtol=1e-6, atol=1e-18)
    assert worst < 1e-3


def test_kalman_tracks_velocity_from_the_quantised_encoder():
    """With the shipped tuning (config [kalman])."""
    cfg = load_config()
    a, q = kalman_model(T, cfg.kalman.jerk_psd_m2_s5)
    r_base = quantisation_variance(0.125e-3)
    t, y, z = quantised_motion()
    x = np.array([z[0], 0.0, 0.0])
    p = np.diag([r_base, 1e-4, 1e-2])
    xp, pp = np.zeros(3), np.zeros((3, 3))
    velocity_error = []
    for k, zk in enumerate(z):
        r = adaptive_r(r_base, cfg.kalman.adaptive_gain, x[1], cfg.kalman.adaptive_velocity_ref_m_s)
        kalman_step_into(x, p, a, q, zk, True, r, xp, pp)
        if k > 500:
            true_v = 0.1 * math.cos(2.0 * t[k]) + 0.09 * math.cos(9.0 * t[k])
            velocity_error.append(x[1] - true_v)
    # a one-count (0.125 mm) encoder differentiated naively jumps 62.5 mm/s per sample
    naive = np.diff(z) / T - (0.1 * np.cos(2.0 * t[1:]) + 0.09 * np.cos(9.0 * t[1:]))
    rms_kalman = np.sqrt(np.mean(np.square(velocity_error)))
    rms_naive = np.sqrt(np.mean(np.square(naive[500:])))
    assert rms_kalman < 0.6 * rms_naive
    assert rms_kalman < 0.03           # 30 mm/s on a 190 mm/s, 9 rad/s motion


def test_adaptive_r_is_eq_7_50():
    assert adaptive_r(2.0, 10.0, 0.0, 1e-3) == pytest.approx(20.0)
    assert adaptive_r(2.0, 10.0, 3e-3, 1e-3) == pytest.approx(20.0 / 10.0)


def test_kalman_q_is_positive_definite():
    _, q = kalman_model(T, 1.0)
    assert np.all(np.linalg.eigvalsh(q) > 0)


def test_filter_matches_scipy_lsim():
    wn_hz, zeta = 5.0, 0.7
    ad, bd = second_order_filter(T, wn_hz, zeta)
    wn = 2 * math.pi * wn_hz
    t = np.arange(2000) * T
    u = np.sin(3.0 * t) + (t > 1.0)
    sys = signal.lti([wn * wn], [1.0, 2 * zeta * wn, wn * wn])
    _, expected, _ = signal.lsim(sys, u, t, interp=False)      # zero-order hold input
    state = np.zeros(3)
    out = np.empty_like(t)
    second = np.empty_like(t)
    for k, uk in enumerate(u):
        out[k] = state[0]
        second[k] = filter_step(state, ad, bd, wn, zeta, uk)
    np.testing.assert_allclose(out, expected, atol=1e-9)
    # s^2 F(s) u: the filtered second derivative of a sine is -9 F(s) sin in steady state
    assert np.max(np.abs(second[300:450] + 9.0 * out[300:450])) < 0.05      # of amplitudes ~9


def lugre_vector():
    return load_config().friction.vector.copy()


def test_lugre_observer_steady_state_is_the_static_map():
    """z' = 0 at constant v: Ff = g(v) sgn(v) + sigma2 v (eq. 7.30-7.32, Table 6.1)."""
    fp = lugre_vector()
    for v, (a0, a1, vs, s2) in ((0.02, (12.1994, 10.6468, 0.010, 131.6)),
                                (-0.03, (-15.0, -5.3903, -0.020, 75.3))):
        z = np.zeros(1)
        for _ in range(2000):
            ff = lugre_observer_step(fp, 0.0, z, 0, v, 0.0, T)
        g = a0 + a1 * math.exp(-(v / vs) ** 2)
        assert ff == pytest.approx(abs(g) * math.copysign(1.0, v) + s2 * v, rel=1e-6)


def test_lugre_observer_presliding_is_a_spring():
    """At small displacement from rest the bristles act as sigma0 z (Table 6.2)."""
    fp = lugre_vector()
    z = np.zeros(1)
    v = 1e-5
    for _ in range(5):
        ff = lugre_observer_step(fp, 0.0, z, 0, v, 0.0, T)
    displacement = 5 * v * T
    assert ff == pytest.approx(238970.9 * displacement + 1894.4 * v + 131.6 * v, rel=0.02)


def test_lugre_observer_gain_term():
    """eq. 7.30's -k e term pulls z against the position error."""
    z0, z1 = np.zeros(1), np.zeros(1)
    lugre_observer_step(lugre_vector(), 0.0, z0, 0, 0.0, 0.001, T)
    lugre_observer_step(lugre_vector(), 50.0, z1, 0, 0.0, 0.001, T)
    assert z0[0] == 0.0 and z1[0] == pytest.approx(-50.0 * 0.001 * T)


def test_rls_recovers_a_mass_from_filtered_regression():
    """eq. 7.37 (corrected): m F(s)[s^2 y + g] = F(s) F_s with the true m = 4.35 kg."""
    m_true, g = 4.35, 9.81
    wn_hz, zeta = 3.0, 0.7
    wn = 2 * math.pi * wn_hz
    ad, bd = second_order_filter(T, wn_hz, zeta)
    t = np.arange(5000) * T
    y = 0.15 + 0.02 * np.sin(4.0 * t)
    acc = -0.02 * 16.0 * np.sin(4.0 * t)
    rng = np.random.default_rng(0)
    force = m_true * (acc + g) + 0.3 * rng.standard_normal(len(t))
    fy, fg, ff = np.array([y[0], 0.0, y[0]]), np.array([g, 0.0, g]), np.array([force[0], 0.0, force[0]])
    theta, p = np.array([1.35]), np.array([1.0])
    for k in range(len(t)):
        phi = filter_step(fy, ad, bd, wn, zeta, y[k]) + fg[0]
        filter_step(fg, ad, bd, wn, zeta, g)
        psi = ff[0]
        filter_step(ff, ad, bd, wn, zeta, force[k])
        rls_step(theta, p, 0, phi, psi, 0.998, 10.0, 70.0)
    assert theta[0] == pytest.approx(m_true, rel=0.01)


def test_rls_follows_a_mass_change_and_stays_bounded():
    theta, p = np.array([0.0]), np.array([1.0])
    for k in range(4000):
        m = 2.0 if k < 2000 else 8.0
        rls_step(theta, p, 0, 9.81, m * 9.81, 0.99, 10.0, 70.0)
        assert 0.0 <= theta[0] <= 70.0 and p[0] <= 10.0
    assert theta[0] == pytest.approx(8.0, rel=1e-3)


def test_load_pressure_and_inverse_dynamics_are_the_free_body_balances():
    area = math.pi * 0.006 ** 2
    # piston + rod (0.6 kg) pushing 20 N through the load cell against 5 N friction, accelerating 2 m/s^2
    pl = load_pressure(20.0, 5.0, 0.6, 2.0, 9.81, area)
    assert pl * area == pytest.approx(20.0 + 5.0 + 0.6 * (2.0 + 9.81))
    # the pressure needed to accelerate 0.6 + 3 kg at 1 m/s^2 against gravity and 4 N of friction
    plr = piston_inverse_dynamics(3.6, 1.0, 9.81, 4.0, area)
    assert plr * area == pytest.approx(3.6 * 10.81 + 4.0)

