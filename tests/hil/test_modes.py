"""The hexapod's modal model (`hydrapod design modes`): a hand-worked one-leg case, the
linearisation against the emulator's own nonlinear response, and the command."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.linalg import expm

from hil.cli import main
from hil.design.modes import blocks, modal_model, pose_quaternion, sealed_modes, state_matrices
from physics import hydraulics as hy
from plant_emulator.params import load_config
from plant_emulator.rigs import HexapodRig

PERIOD_S = 0.002

CIRCLE_START_M = np.array([0.2, 0.0, 0.631])
# friction down to a trace: the linear model takes the seals' sliding slope, the emulator's
# LuGre bristles would hold a 0.1 mm perturbation in pre-sliding
LOW_FRICTION = {"friction": {"alpha0_pos_n": 0.01, "alpha1_pos_n": 0.0, "alpha0_neg_n": -0.01,
                             "alpha1_neg_n": 0.0}}


def test_one_leg_without_leakage_oscillates_at_the_oil_columns_frequency():
    """Closed-centre valve at null, no leakage, no friction: a mass on two oil columns,
    omega^2 = A^2 (beta_A / V_A + alpha^2 beta_B / V_B) / m, undamped."""
    cfg = load_config(overrides={"valve": {"supply_lap_pct": 0.0, "return_lap_pct": 0.0},
                                 "chambers": {"cross_leakage_l_min_per_bar": 0.0, "seal_leakage_l_min_per_bar": 0.0,
                                              "air_fraction_pct": 0.0}})
    mass, y, pa, pb = 5.0, 0.1, 12e5, 9e5
    a, _, stiffness, _ = state_matrices(cfg, np.array([[mass]]), np.zeros((1, 1)), np.array([y]), np.array([pa]),
                                        np.array([pb]), np.zeros(1), cfg.actuator.supply_pressure_pa, 0.0)
    beta = 1.0 / (1.0 / cfg.hp[hy.HP_BETA_OIL] + 1.0 / cfg.hp[hy.HP_BETA_WALL])
    area, alpha = cfg.area_a_m2, cfg.alpha
    va = cfg.hp[hy.HP_VA0] + area * y
    vb = cfg.hp[hy.HP_VB0] + alpha * area * (cfg.hp[hy.HP_STROKE] - y)
    k_hand = area ** 2 * (beta / va + alpha ** 2 * beta / vb)
    assert stiffness[0] == pytest.approx(k_hand, rel=1e-6)
    values = np.linalg.eigvals(a)
    pair = values[np.abs(values.imag) > 1e-6]
    assert len(pair) == 2
    assert np.abs(pair.imag).max() == pytest.approx(math.sqrt(k_hand / mass), rel=1e-4)
    assert np.abs(pair.real).max() < 1e-6 * math.sqrt(k_hand / mass)


def test_one_sealed_leg_adds_the_seals_bristles_in_parallel_with_its_oil_columns():
    """Load-holding valves closed (ports 0: no valve flow, no valve-side leak), the seals in
    pre-sliding: omega^2 = (K_oil + sigma0) / m, damping 2 zeta omega m = sigma1 + sigma2; the
    leg keeps its oil-column stiffness, the spool no longer reaches it."""
    cfg = load_config(overrides={"chambers": {"seal_leakage_l_min_per_bar": 0.0, "air_fraction_pct": 0.0}})
    mass, y, pa, pb, sigma0, damping = 5.0, 0.1, 12e5, 9e5, 2e5, 1500.0
    a, _, stiffness, flow_gain = state_matrices(cfg, np.array([[mass]]), np.zeros((1, 1)), np.array([y]),
                                                np.array([pa]), np.array([pb]), np.zeros(1),
                                                cfg.actuator.supply_pressure_pa, damping, ports=0.0,
                                                seal_stiffness=sigma0)
    beta = 1.0 / (1.0 / cfg.hp[hy.HP_BETA_OIL] + 1.0 / cfg.hp[hy.HP_BETA_WALL])
    area, alpha = cfg.area_a_m2, cfg.alpha
    va = cfg.hp[hy.HP_VA0] + area * y
    vb = cfg.hp[hy.HP_VB0] + alpha * area * (cfg.hp[hy.HP_STROKE] - y)
    k_oil = area ** 2 * (beta / va + alpha ** 2 * beta / vb)
    assert stiffness[0] == pytest.approx(k_oil, rel=1e-6) and flow_gain[0] == 0.0
    values = np.linalg.eigvals(a)
    pair = values[np.abs(values.imag) > 1e-6]
    assert len(pair) == 2
    w = math.sqrt((k_oil + sigma0) / mass)
    assert abs(pair[0]) == pytest.approx(w, rel=1e-4)
    assert -pair[0].real == pytest.approx(damping / (2 * mass), rel=1e-4)


def test_the_sealed_modes_combine_both_bristle_sides_half_a_period_each():
    """`sealed_modes`: frequency 2 / (1/f+ + 1/f-) of the two sides' models, paired one to one;
    at home x and y alike (the platform's symmetry)."""
    cfg = load_config()
    home = HexapodRig(cfg).geometry.home_position_m
    modes = sealed_modes(cfg, home)
    by_axis = {m["axis"]: m for m in modes}
    assert {"x", "y", "yaw"} <= set(by_axis)
    for m in modes:
        f_plus, f_minus = m["frequency_hz_sides"]
        assert m["frequency_hz"] == pytest.approx(2.0 / (1.0 / f_plus + 1.0 / f_minus))
        assert min(f_plus, f_minus) < m["frequency_hz"] < max(f_plus, f_minus)
    assert by_axis["x"]["frequency_hz"] == pytest.approx(by_axis["y"]["frequency_hz"], rel=1e-3)
    assert by_axis["x"]["damping_ratio"] == pytest.approx(by_axis["y"]["damping_ratio"], rel=1e-3)


@pytest.mark.parametrize("bristles_n", [None, (1.7, -1.1, -4.2, 8.2, -7.2, -2.0)])
def test_the_sealed_response_is_the_emulators_under_a_push(bristles_n):
    """`sealed_response` against the emulator itself: the hexapod held at home, sealed (ports
    closed), its bristles as the sealing left them or deflected as a HIL sealing once left them
    (8 N on two legs: there the linearised seals gave 1.33x too little damping), pushed 2 N
    along x for 20 ms; both responses fitted alike: frequency and damping within 10 %."""
    from hil.design.modes import sealed_response
    from hil.scenarios.kick import free_mode
    from physics import lugre
    from protocol.enums import KickAxis
    cfg = load_config()
    fp = cfg.friction.vector
    rig = HexapodRig(cfg)
    rig.ports_open[:] = 0.0
    for _ in range(300):
        rig.advance(PERIOD_S)
    if bristles_n is not None:                     # the chambers carry what the bristles now hold
        sigma0 = np.where(np.array(bristles_n) >= 0.0, fp[lugre.S0_POS], fp[lugre.S0_NEG])
        held = sigma0 * rig.state[:, hy.S_Z]
        rig.state[:, hy.S_Z] = np.array(bristles_n) / sigma0
        rig.state[:, hy.S_PA] += (np.array(bristles_n) - held) / cfg.area_a_m2
        for _ in range(300):
            rig.advance(PERIOD_S)
    pose = rig.platform_pose()[0].copy()
    pressures = rig.state[:, [hy.S_PA, hy.S_PB]].T.copy()
    rig.kick(int(KickAxis.X), 2.0, 0.02)
    measured = []
    for _ in range(750):
        rig.advance(PERIOD_S)
        measured.append(rig.platform_pose()[0][0])
    model = sealed_response(cfg, pose, pressures, 0, 2.0, 0.02, 1.5)
    skip = 11 + 5                                  # the push and 10 ms after it, as the analysis
    (mine, _), (theirs, _) = (free_mode(np.asarray(y)[skip:-2], PERIOD_S) for y in (measured, model))
    assert mine["frequency_hz"] == pytest.approx(theirs["frequency_hz"], rel=0.10)
    assert mine["damping_ratio"] == pytest.approx(theirs["damping_ratio"], rel=0.10)


def test_the_linear_model_predicts_the_emulators_response_to_a_valve_step():
    """From the operating point at the circle's start, 0.5 % more spool on leg 1 for 30 ms:
    the linear model's leg strokes and pressures against the emulator's own integration."""
    cfg = load_config(overrides=LOW_FRICTION)
    model = modal_model(cfg, CIRCLE_START_M)
    assert model.converged
    rig = HexapodRig(cfg)
    rig.mechanism.set_pose(CIRCLE_START_M, pose_quaternion((0.0, 0.0, 0.0)))
    rig.mechanism.data.qvel[:] = 0.0
    strokes = rig.mechanism.data.qpos[rig.mechanism.slide_qpos] + rig.home_length_m - rig.geometry.leg_min_m
    np.testing.assert_allclose(strokes, model.strokes_m, atol=1e-9)
    rig.state[:, hy.S_Y] = strokes
    rig.state[:, hy.S_PA], rig.state[:, hy.S_PB] = model.pressure_a_pa, model.pressure_b_pa
    rig.state[:, hy.S_SPOOL] = model.spool_offset
    step = np.zeros(6)
    step[0] = 0.005
    rig.command[:] = model.spool_offset + step
    period, cycles = 0.002, 15
    n = len(model.a)
    augmented = np.zeros((n + 6, n + 6))
    augmented[:n, :n], augmented[:n, n:] = model.a * period, model.b * period
    transition = expm(augmented)
    x = np.zeros(n)
    for _ in range(cycles):
        rig.advance(period)
        x = transition[:n, :n] @ x + transition[:n, n:] @ step
    q, _, pa, _, _ = blocks(6)
    moved = rig.state[:, hy.S_Y] - model.strokes_m
    assert abs(moved[0]) > 1e-4                                   # a gross motion of the driven leg
    np.testing.assert_allclose(x[q], moved, atol=0.1 * abs(moved[0]))
    rise = rig.state[:, hy.S_PA] - model.pressure_a_pa
    np.testing.assert_allclose(x[pa], rise, atol=0.1 * abs(rise[0]))


def test_modes_command_prints_the_table_and_json(capsys, tmp_path):
    assert main(["design", "modes", "--pose", "200,0,631,0,0,0", "--json", "--plot", str(tmp_path)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["converged"] and len(doc["legs"]["stiffness_n_mm"]) == 6
    assert all(k > 0 for k in doc["legs"]["stiffness_n_mm"])
    assert (tmp_path / "modes.png").is_file()
    # the pose's symmetry: legs 1 and 2 mirror each other about the x axis
    assert doc["legs"]["static_force_n"][0] == pytest.approx(doc["legs"]["static_force_n"][1], rel=1e-4)


def test_modes_command_adds_the_sealed_modes(capsys):
    """`--sealed`: the model hex-kick compares with, beside the open-valve one."""
    assert main(["design", "modes", "--sealed", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    sealed = {m["axis"]: m for m in doc["sealed"]}
    assert {"x", "y", "yaw"} <= set(sealed)
    for m in sealed.values():
        low, high = sorted(m["frequency_hz_sides"])
        assert low < m["frequency_hz"] < high
    assert main(["design", "modes", "--sealed"]) == 0
    assert "sealed (valves HOLD" in capsys.readouterr().out
