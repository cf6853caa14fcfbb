"""sha-classical's pure parts: the controller's D term against SciPy, the loop identified from
a window's data, and the P loop's steady-error predictions (the HIL run is in test_hil.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from firmware_py.motion_control.joint_space import filtered_derivative
from hil.scenarios.sha_classical import (
    DERIVATIVE_FILTER_HZ,
    friction_at_rest_n,
    identify_loop,
    p_steady_error_predictions,
)
from physics.constants import MM
from plant_emulator.params import load_config as load_emulator_config

PERIOD_S = 0.002


def _derivative_by_scipy(y: np.ndarray) -> np.ndarray:
    """(1 - a) / T (1 - z^-1) / (1 - a z^-1) applied to y, starting at rest on y[0]."""
    alpha = np.exp(-2 * np.pi * DERIVATIVE_FILTER_HZ * PERIOD_S)
    difference = np.diff(y, prepend=y[0]) / PERIOD_S
    return signal.lfilter([1.0 - alpha], [1.0, -alpha], difference)


def test_the_d_terms_filtered_derivative_is_scipys_first_order_filter():
    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(0.0, 1e-4, 800)) + 0.15
    alpha = np.exp(-2 * np.pi * DERIVATIVE_FILTER_HZ * PERIOD_S)
    state = np.array([0.0, y[0]])
    mine = np.array([filtered_derivative(state, v, alpha, PERIOD_S) for v in y])
    np.testing.assert_allclose(mine, _derivative_by_scipy(y), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kp, ki, kd, name", [(85.0, 0.0, 0.0, "p"), (85.0, 460.0, 0.0, "pi"),
                                              (85.0, 0.0, 10.0, "pd"), (85.0, 460.0, 10.0, "pid")])
def test_a_windows_loop_and_gains_are_identified_from_its_data(kp, ki, kd, name):
    """u built by the control law (SI gains: V/m, V/(m s), V s/m) from a quantised step
    response, plus an integral carried in from before the window."""
    t = np.arange(1000) * PERIOD_S
    y = 0.150 + 0.010 * (1.0 - np.exp(-t / 0.08) * np.cos(40 * t))
    y = np.round(y / (0.125 * MM)) * 0.125 * MM                      # the encoder's counts
    error = 0.160 - y
    u = kp * error + ki * np.cumsum(error) * PERIOD_S - kd * _derivative_by_scipy(y) + 0.3
    found = identify_loop(u, error, y, PERIOD_S, u_max_v=10.0)
    assert found["loop"] == name
    assert found["kp"] == pytest.approx(kp, rel=1e-6)
    assert found["ki"] == pytest.approx(ki, abs=1e-6 * kp)
    assert found["kd"] == pytest.approx(kd, abs=1e-6 * kp)


def test_saturated_samples_are_left_out_of_the_fit():
    t = np.arange(1000) * PERIOD_S
    y = 0.150 + 0.010 * (1.0 - np.exp(-t / 0.08) * np.cos(40 * t))
    error = 0.160 - y
    u = np.clip(200.0 * error, -1.0, 1.0)                           # saturates while |e| > 5 mm
    found = identify_loop(u, error, y, PERIOD_S, u_max_v=1.0)
    assert found["loop"] == "p" and found["kp"] == pytest.approx(200.0, rel=1e-6)


def test_friction_at_rest_is_the_seals_and_the_guides_on_the_side_of_the_motion():
    cfg = load_emulator_config()
    up, down = friction_at_rest_n(cfg, 0.0, True), friction_at_rest_n(cfg, 0.0, False)
    # Tables 6.1 (seals) and D.1 (guide, Fs = Fc): 12.2 + 10.9 sliding, + 10.6 breakaway up
    assert up == pytest.approx((12.1994 + 10.9, 12.1994 + 10.6468 + 10.9), abs=1e-3)
    assert down == pytest.approx((15.0 + 10.9, 15.0 + 5.3903 + 10.9), abs=1e-3)


def test_the_p_loops_steady_error_grows_with_the_friction_left_by_an_upward_stop():
    cfg = load_emulator_config()
    up = p_steady_error_predictions(cfg, 0.160, 3.0, 85.0, upward=True)
    down = p_steady_error_predictions(cfg, 0.160, 3.0, 85.0, upward=False)
    assert up["frictionless_m"] == down["frictionless_m"] > 0.0
    assert up["frictionless_m"] < up["with_friction_m"][0] < up["with_friction_m"][1]
    assert down["with_friction_m"][0] < down["with_friction_m"][1] < down["frictionless_m"]
    # eq. 7.4 is linear in 1/Kp; the chambers' holding spool too
    half = p_steady_error_predictions(cfg, 0.160, 3.0, 170.0, upward=True)
    assert half["eq_7_4_m"] == pytest.approx(up["eq_7_4_m"] / 2)
    assert half["frictionless_m"] == pytest.approx(up["frictionless_m"] / 2)
