"""Appendix D's fits on falls of known friction (the HIL run against the emulator: test_hil.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.design.guide_fit import Fall, fall_d3, fall_d4, fit_stribeck, fit_viscous, friction_d2
from physics.constants import GRAVITY_M_S2

PERIOD = 2e-3
COUNT = 0.125e-3                     # the encoder's step
FC, SV = 10.9, 9.1                   # Table D.1: N, N s/m


def _record(load, release_s, static_n=FC, stribeck_m_s=0.3, seconds=0.5):
    """A fall as the encoder records it: counts, from PRE before the valve step."""
    mass = 1.35 + load
    t = np.arange(-10, int(seconds / PERIOD)) * PERIOD
    s = fall_d3(t, release_s, mass, FC, SV, static_n, stribeck_m_s, 3.0)
    return Fall(load, mass, t, np.round(s / COUNT) * COUNT)


def test_the_closed_form_fall_is_the_integrated_one_without_a_stribeck_hump():
    t = np.arange(0, 250) * PERIOD
    for load in (0.0, 6.0):
        closed = fall_d4(t, 0.004, 1.35 + load, FC, SV)
        integrated = fall_d3(t, 0.004, 1.35 + load, FC, SV, FC, 0.3, 3.0)
        assert np.max(np.abs(closed - integrated)) < 0.2e-3


def test_a_slide_held_by_its_static_friction_does_not_fall():
    t = np.arange(0, 100) * PERIOD
    assert not np.any(fall_d3(t, 0.0, 1.35, FC, SV, 1.35 * GRAVITY_M_S2 + 0.1, 0.3, 3.0))


def test_eq_d4_is_found_from_the_encoder_counts_of_falls_at_several_loads():
    falls = [_record(load, release) for load, release in ((0.0, 0.006), (3.0, 0.003), (6.0, 0.005))]
    fit = fit_viscous(falls)
    assert fit["coulomb_n"] == pytest.approx(FC, rel=0.02)
    assert fit["viscous_ns_m"] == pytest.approx(SV, rel=0.05)
    assert fit["release_s"] == pytest.approx([0.006, 0.003, 0.005], abs=1e-3)
    assert min(fit["fit"]) > 0.998                  # the counts alone: 1 - 0.0013 at 0 kg


@pytest.mark.parametrize("load, static_n, stribeck_m_s", [(1.0, 16.0, 0.3), (6.0, 30.0, 0.6)])
def test_a_stribeck_hump_is_found_and_none_where_there_is_none(load, static_n, stribeck_m_s):
    humped = [_record(load, 0.004, static_n, stribeck_m_s), _record(load, 0.006, static_n, stribeck_m_s)]
    found = fit_stribeck(humped, [0.004, 0.006], FC, SV, 3.0)
    assert found["identifiable"]
    assert found["static_n"] == pytest.approx(static_n, rel=0.05)
    assert found["stribeck_m_s"] == pytest.approx(stribeck_m_s, rel=0.15)
    flat = fit_stribeck([_record(load, 0.004)], [0.004], FC, SV, 3.0)
    assert not flat["identifiable"] and flat["static_n"] - FC < 1.0


def test_eq_d2_reads_the_weight_where_the_slide_rests():
    """Table D.1's Fs column: eq. D.2 at v = 0 is m g whatever holds the slide."""
    fall = _record(3.0, 0.1)
    v, force = friction_d2(fall.s_m, fall.mass_kg, PERIOD, 100.0)
    resting = fall.t_s < 0.1
    assert np.all(v[resting] == 0.0) and force[resting] == pytest.approx(fall.mass_kg * GRAVITY_M_S2)
