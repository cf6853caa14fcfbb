"""Chapter 5.2's identification steps (hil/identification.py) on synthetic data with a known
answer: the gain of a P law, G(s) through Gcl and eq. 5.5, m/sigma/Fe by eq. 5.7, the
complete model of eq. 5.11 and its refinement by eq. 5.12."""

import numpy as np
import pytest
from scipy import signal

from hil import identification as ident

PERIOD_S = 0.002
PLANT = {"b0": 11425.0, "b1": 106.0, "k01": 0.236}          # Table A.3, 150 mm, 0 kg (k01 in m/s/V)


def test_proportional_gain_from_the_logged_valve_input():
    rng = np.random.default_rng(1)
    error = rng.uniform(-0.01, 0.01, 200)
    u = 150.0 * error + 0.3 + rng.normal(0, 1e-3, 200)
    k, u0 = ident.proportional_gain(u, error)
    assert k == pytest.approx(150.0, rel=1e-3) and u0 == pytest.approx(0.3, abs=1e-3)


@pytest.mark.parametrize("k_v_m", [150.0, 250.0])
def test_closed_loop_fit_and_eq_5_5_recover_the_plant(k_v_m):
    t = np.arange(76) * PERIOD_S
    n0, a2, a1, a0 = ident.closed_loop_of(PLANT, k_v_m)
    step = 0.01
    dy = step * ident.closed_loop_step(n0, a2, a1, a0, t, PERIOD_S)
    dy += np.random.default_rng(2).normal(0, 2e-5, len(t))
    gcl = ident.fit_closed_loop(t, dy, step, PERIOD_S, k_v_m, (9000.0, 90.0, 0.2))
    plant = ident.open_loop_from_closed(gcl, k_v_m)
    assert gcl["fit"] > 0.99
    for key in ("b0", "b1", "k01"):
        assert plant[key] == pytest.approx(PLANT[key], rel=0.03), key


def test_closed_loop_step_is_the_scipy_step_delayed():
    t = np.arange(50) * PERIOD_S
    y = ident.closed_loop_step(4e5, 106.0, 11425.0, 4e5, t, 2 * PERIOD_S)
    _, reference = signal.step(signal.lti([4e5], [1.0, 106.0, 11425.0, 4e5]), T=t[:-2])
    np.testing.assert_allclose(y[2:], reference, atol=1e-12)
    assert y[0] == y[1] == 0.0


@pytest.mark.parametrize("poles", [(-30.0 + 100.0j, -30.0 - 100.0j, -400.0), (-50.0, -50.0, -50.0)])
def test_the_lti_response_is_scipy_lsim(poles):
    """lsim is the oracle: the same first-order hold, an input not at rest at the first sample,
    distinct and repeated poles (the latter by Ad's powers)."""
    rng = np.random.default_rng(4)
    t = np.arange(120) * PERIOD_S
    u = 3.0 + rng.normal(0.0, 1.0, len(t)).cumsum()
    den = np.real(np.poly(poles))
    for num in ([2e5], [7e3, -4e5]):
        _, reference, _ = signal.lsim(signal.lti(num, den), u, t)
        np.testing.assert_allclose(ident.lti_response(num, den, u, PERIOD_S), reference,
                                   rtol=0.0, atol=1e-9 * np.max(np.abs(reference)))


def test_motion_parameters_from_eq_5_7():
    t = np.arange(400) * PERIOD_S
    y = 0.15 + 0.01 * np.sin(2 * np.pi * 3.0 * t) + 0.004 * np.sin(2 * np.pi * 7.0 * t)
    v = np.gradient(y, PERIOD_S)
    a = np.gradient(v, PERIOD_S)
    m, sigma, fe, area = 2.3, 150.0, 22.0, 1.131e-4
    pl = (m * a + sigma * v + fe) / area
    result = ident.motion_parameters(ident.force_terms(y, pl, area, PERIOD_S, cutoff_hz=50.0))
    assert result["m"] == pytest.approx(m, rel=0.05)
    assert result["sigma"] == pytest.approx(sigma, rel=0.05)
    assert result["fe"] == pytest.approx(fe, rel=0.02)


def test_table_a2_is_eq_5_8_to_5_10_on_tables_a1_and_a3():
    """The thesis's sensibilities follow from its G(s) and motion parameters within 1 % at all
    33 points (sigma in N s/m, the piston area the tables imply): the oracle for the units."""
    from hil.design.thesis import thesis_data
    from plant_emulator.linear_rig import table_a3
    data = thesis_data("chapter5")
    a1, a2, a3 = (np.asarray(t, float) for t in (data["table_A1"]["rows"], data["table_A2"]["rows"], table_a3()))
    area = data["table_A2"]["piston_area_mm2"] * 1e-6
    for row1, row2, row3 in zip(a1, a2, a3):
        for j in range(3):
            m, sigma = row1[1 + 3 * j], row1[2 + 3 * j]
            b0, b1, k01 = row3[1 + 3 * j], row3[2 + 3 * j], row3[3 + 3 * j] * 1e-3
            kx, kd, kp = ident.sensibilities(b0, b1, k01, m, sigma, area)
            assert kx / 1e3 == pytest.approx(row2[1 + 3 * j], rel=0.01)          # kPa/(s V)
            assert kd / 1e6 == pytest.approx(row2[2 + 3 * j], rel=0.01)          # kPa/mm
            assert kp == pytest.approx(row2[3 + 3 * j], rel=0.01)


def test_the_complete_model_inverts_the_sensibilities():
    m, sigma, area = 7.3, 23.4, 1.13e-4
    kx, kd, kp = ident.sensibilities(PLANT["b0"], PLANT["b1"], PLANT["k01"], m, sigma, area)
    model = ident.complete_model(kx, kd, kp, m, sigma, area)
    assert [model[k] for k in ("b0", "b1", "k01")] == pytest.approx([PLANT[k] for k in ("b0", "b1", "k01")])
    assert model["k02"] == pytest.approx(1.0 / (m * PLANT["b0"])) and model["z0"] == pytest.approx(-kp)


def test_the_motion_parameters_quadratic_in_the_position():
    y = np.linspace(0.01, 0.29, 11)
    values = 2.0 - 3.0 * y + 10.0 * y ** 2
    assert ident.quadratic_fit(y, values) == pytest.approx([10.0, -3.0, 2.0])
    assert ident.quadratic_fit(y[:2], values[:2]) is None


def test_eq_4_50_by_least_squares_recovers_the_constants():
    """PL' = Kx xv - Kd y' + Kp PL + c per window, from windows of a simulated load-pressure
    equation with its own operating points."""
    kx, kd, kp = 6.0e7, 2.5e8, -40.0
    rng = np.random.default_rng(3)
    windows = []
    for offset in (2e5, -1e5, 4e5):
        n = 90
        xv, velocity = rng.normal(0, 1.0, n), rng.normal(0, 0.05, n)
        pl = np.empty(n)
        pl[0] = 1e6
        for i in range(1, n):                    # integrate the equation itself
            pl[i] = pl[i - 1] + PERIOD_S * (kx * xv[i - 1] - kd * velocity[i - 1] + kp * pl[i - 1] + offset)
        rate = np.diff(pl) / PERIOD_S
        windows.append((xv[:-1], velocity[:-1], pl[:-1], rate))
    assert ident.load_pressure_fit(windows) == pytest.approx((kx, kd, kp), rel=1e-6)


def test_the_scheduled_model_reads_between_the_points_and_judges_each_from_the_others():
    """Fig. 5.10's table: a spline through the working points (cubic from four), so a
    parameter cubic in the set point is read exactly between them, and exactly again at a
    point left out; the ends, which the others would extrapolate, are not judged."""
    x = np.array([10.0, 30.0, 60.0, 90.0, 120.0, 150.0]) * 1e-3
    b0 = 2e4 - 3e5 * x + 4e6 * x ** 2 - 9e6 * x ** 3
    assert ident.scheduled_parameter(x, b0, 0.075) == pytest.approx(2e4 - 3e5 * 0.075 + 4e6 * 0.075 ** 2
                                                                    - 9e6 * 0.075 ** 3)
    read = ident.leave_one_out(x, b0)
    assert np.isnan(read[0]) and np.isnan(read[-1])
    np.testing.assert_allclose(read[1:-1], b0[1:-1], rtol=1e-9)
    # two points: the straight line between them
    assert ident.scheduled_parameter(x[:2], b0[:2], 0.02) == pytest.approx(0.5 * (b0[0] + b0[1]))


def test_the_complete_model_is_refined_back_to_the_plant_that_made_the_windows():
    """Windows made by eq. 5.11 itself (P loop, reference steps, a load change each): the
    G(s)-only response misses the load's part; the refinement (chapter 5.2.4) started 20 %
    off finds the plant again and fits each window better than G(s) alone."""
    mass, sigma, area, k_v_m = 2.3, 150.0, 1.131e-4, 200.0
    t = np.arange(76) * PERIOD_S
    rng = np.random.default_rng(3)
    windows = []
    for step, load in ((0.01, 15.0), (-0.008, -12.0), (0.005, 8.0)):
        load_n = load * (1.0 - np.exp(-t / 0.02)) + rng.normal(0.0, 0.3, len(t))
        dy = ident.complete_response(PLANT, k_v_m, mass, sigma, area, t, step, load_n, PERIOD_S)
        windows.append({"t": t, "dy": dy, "step_m": step, "k_v_m": k_v_m, "load_n": load_n})
    alone = [ident.fit_index(w["dy"], w["step_m"] * ident.closed_loop_step(
        *ident.closed_loop_of(PLANT, k_v_m), t, PERIOD_S)) for w in windows]
    assert all(ident.complete_fits(PLANT, mass, sigma, area, windows, PERIOD_S) > 0.999)
    start = {key: value * factor for (key, value), factor in zip(PLANT.items(), (1.2, 0.8, 1.2))}
    refined = ident.refine_complete(start, mass, sigma, area, windows, PERIOD_S)
    for key in ("b0", "b1", "k01"):
        assert refined[key] == pytest.approx(PLANT[key], rel=0.03), key
    assert all(ident.complete_fits(refined, mass, sigma, area, windows, PERIOD_S) > np.array(alone))
