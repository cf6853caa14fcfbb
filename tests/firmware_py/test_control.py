"""Controllers of chapters 7.4-7.5: the gain schedule against SciPy, the anti-windup, and
closed-loop steps against the linear plants of Table A.3 (behind the simulated rig's valve
and sensors)."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from firmware_py.config import load_config
from firmware_py.motion_control.joint_space import (
    ADAPTIVE,
    PI,
    ST_KI,
    ST_KP,
    ST_MASS,
    pi_antiwindup,
    schedule_eval,
    spline_coefficients,
)
from hil.design.simulate import linear_step
from hil.metrics import step_response
from plant_emulator.params import load_config as load_emulator_config

T = 0.002


@pytest.fixture(scope="module")
def cfg():
    return load_config()


def test_schedule_is_table_7_2_at_the_nodes(cfg):
    breaks = cfg.adaptive.table_position_m
    coef = spline_coefficients(breaks, cfg.adaptive.table_kp)
    for j, load in enumerate(cfg.adaptive.table_load_kg):
        for i, y in enumerate(breaks):
            expected = cfg.adaptive.table_kp[j, i]
            assert schedule_eval(breaks, coef, cfg.adaptive.table_load_kg, y, load) == pytest.approx(expected)
    # Table 7.2, 120 mm, 6 kg: Kp = 0.085 V/mm
    assert schedule_eval(breaks, coef, cfg.adaptive.table_load_kg, 0.120, 6.0) == pytest.approx(85.0)


def test_schedule_between_nodes_matches_scipy(cfg):
    breaks, loads = cfg.adaptive.table_position_m, cfg.adaptive.table_load_kg
    coef = spline_coefficients(breaks, cfg.adaptive.table_ki)
    rng = np.random.default_rng(1)
    for y, m in zip(rng.uniform(0.0, 0.31, 200), rng.uniform(-1.0, 7.0, 200)):
        yc, mc = np.clip(y, breaks[0], breaks[-1]), np.clip(m, loads[0], loads[-1])
        per_load = [CubicSpline(breaks, row, bc_type="natural")(yc) for row in cfg.adaptive.table_ki]
        expected = np.polyval(np.polyfit(loads, per_load, 2), mc)           # the quadratic through 3 loads
        assert schedule_eval(breaks, coef, loads, y, m) == pytest.approx(expected, rel=1e-9)


def test_schedule_is_smooth(cfg):
    breaks = cfg.adaptive.table_position_m
    coef = spline_coefficients(breaks, cfg.adaptive.table_kp)
    ys = np.linspace(breaks[0], breaks[-1], 3001)
    values = np.array([schedule_eval(breaks, coef, cfg.adaptive.table_load_kg, y, 2.0) for y in ys])
    slope = np.diff(values) / np.diff(ys)
    assert np.max(np.abs(np.diff(slope))) < 1.0          # no kinks: the slope changes continuously


def test_antiwindup_freezes_the_integral_in_saturation():
    integral = np.zeros(1)
    u = pi_antiwindup(1.0, integral, 0, 100.0, 10.0, 0.0, T, 10.0)
    assert u == 10.0 and integral[0] == 0.0                # saturated, error pushes further: frozen
    integral[0] = 5.0
    u = pi_antiwindup(-0.01, integral, 0, 100.0, 10.0, 0.0, T, 10.0)
    assert u == 10.0                                       # -1 + 50 V saturates at 10 V ...
    assert integral[0] == pytest.approx(5.0 - 0.01 * T)   # ... but the error pulls out: integrates
    integral[0] = 0.0
    u = pi_antiwindup(0.001, integral, 0, 100.0, 10.0, 0.5, T, 10.0)
    assert u == pytest.approx(0.5 + 0.1) and integral[0] == pytest.approx(0.001 * T)


LOADS = (0.0, 3.0, 6.0)
NOISELESS = {"sensors": {"load_cell_noise_n": 0.0, "pressure_noise_bar": 0.0}}


def step_metrics(t, y, y0, step):
    """Overshoot (%) and 5 % settling time (s) of a step from y0 by `step` (the HIL metric)."""
    m = step_response(t, y, y0, step)
    return m["overshoot_pct"], m["settling_s"]


def closed_loop_step(cfg, mode, position_mm, load_index, step_mm=10.0, seconds=2.0):
    """The joint pipeline on Table A.3's plant at a set point (`hil.design.simulate.linear_step`)."""
    return linear_step(cfg, load_emulator_config(overrides=NOISELESS), mode, position_mm, LOADS[load_index],
                       step_mm * 1e-3, seconds)


@pytest.mark.parametrize("position_mm", [60, 150, 240])
@pytest.mark.parametrize("load_index", [0, 1, 2])
def test_pi_step_is_in_the_thesis_range(cfg, position_mm, load_index):
    """Chapter 7.6.1: PI, 10 mm steps: overshoot about 25 %, settled near 0.5 s."""
    t, y, y0, _ = closed_loop_step(cfg, PI, position_mm, load_index)
    overshoot, settling = step_metrics(t, y, y0, 0.010)
    assert 12.0 <= overshoot <= 35.0, f"overshoot {overshoot:.1f} %"
    assert 0.2 <= settling <= 0.7, f"settling {settling:.3f} s"
    assert abs(y[-1] - y0 - 0.010) < 0.3e-3


@pytest.mark.parametrize("position_mm", [60, 150, 240])
@pytest.mark.parametrize("load_index", [0, 1, 2])
def test_adaptive_step_is_stable_and_estimates_the_load(cfg, position_mm, load_index):
    t, y, y0, jc = closed_loop_step(cfg, ADAPTIVE, position_mm, load_index)
    overshoot, settling = step_metrics(t, y, y0, 0.010)
    assert abs(y[-1] - y0 - 0.010) < 0.3e-3
    assert overshoot < 40.0 and settling < 1.5
    assert jc.st[0, ST_MASS] == pytest.approx(1.35 + LOADS[load_index], abs=0.1)
    # scheduled gains: Table 7.2 at the position and the estimated external load, Ki detuned
    load = jc.st[0, ST_MASS] - cfg.testbench.slide_mass_kg
    table = cfg.adaptive
    kp = schedule_eval(table.table_position_m, spline_coefficients(table.table_position_m, table.table_kp),
                       table.table_load_kg, y[-1], load)
    ki = schedule_eval(table.table_position_m, spline_coefficients(table.table_position_m, table.table_ki),
                       table.table_load_kg, y[-1], load)
    assert jc.st[0, ST_KP] == pytest.approx(kp, rel=1e-3)
    assert jc.st[0, ST_KI] == pytest.approx(cfg.adaptive.ki_scale * ki, rel=1e-3)
