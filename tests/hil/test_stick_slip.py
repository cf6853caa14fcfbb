"""The stick-slip model and the cycle measure (the HIL run against the model: test_hil.py)."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_py.config import load_config as load_controller_config
from hil.design.calibration import linearise, state_space
from hil.design.stick_slip import CYCLING_MIN_M, limit_cycle, predict
from physics.constants import MM
from plant_emulator.params import load_config as load_emulator_config

PERIOD_S = 0.002


def test_a_sawtooths_spread_and_period_are_measured():
    t = np.arange(2000) * PERIOD_S
    saw = 0.4 * MM * ((t / 0.18) % 1.0) + 0.05 * MM * t         # a slow drift is no cycle
    cycle = limit_cycle(saw)
    assert cycle["cycling"]
    assert cycle["spread_m"] == pytest.approx(0.36 * MM, rel=0.03)
    assert cycle["period_s"] == pytest.approx(0.18, rel=0.02)


def test_a_flat_error_and_a_short_one_do_not_cycle():
    rng = np.random.default_rng(1)
    assert not limit_cycle(rng.normal(0.0, 0.01 * MM, 2000))["cycling"]
    assert limit_cycle(np.full(5, np.nan)) == {"spread_m": pytest.approx(np.nan, nan_ok=True), "period_s": None,
                                               "cycling": False}


def test_the_state_space_at_rest_is_the_calibrations_linearisation():
    cfg = load_emulator_config()
    space, point = state_space(cfg, 150.0, 3.0), linearise(cfg, 150.0, 3.0)
    np.testing.assert_allclose(np.linalg.eigvals(space.a), point.poles)
    # holding more force needs more load pressure: the operating point moves with it
    assert state_space(cfg, 150.0, 3.0, 20.0).x0[1] > space.x0[1]


@pytest.mark.parametrize("speed_mm_s, cycles", [(2.0, False), (8.0, True), (20.0, False)])
def test_the_model_sticks_and_slips_only_in_the_stribeck_region(speed_mm_s, cycles):
    model = predict(load_emulator_config(), load_controller_config(), speed_mm_s * MM, 6.0, 0.15, 4.0)
    assert model["cycling"] is cycles
    assert (model["spread_m"] >= CYCLING_MIN_M) is cycles


def test_without_the_stribeck_drop_there_is_no_cycle():
    """6.2: the cause is friction at rest above friction at a small speed (alpha1 > 0)."""
    flat = load_emulator_config(overrides={"friction": {"alpha1_pos_n": 0.0, "alpha1_neg_n": 0.0}})
    model = predict(flat, load_controller_config(), 8.0 * MM, 6.0, 0.15, 4.0)
    assert not model["cycling"] and model["spread_m"] < 0.05 * MM
