"""`hydrapod design capacity` (hil/design/capacity.py): the thesis's movements' utilisation
of the legs' capacity, and the time scale each needs."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from hil.design.capacity import LegCapacity, needed_scale, utilisation
from tests.support.cli import hydrapod


def test_the_utilisation_falls_with_the_time_scale_and_is_one_at_the_needed_scale():
    cfg = load_config()
    fast = utilisation(cfg, "diagonal", 0.0, 25.0, 1.0)
    slow = utilisation(cfg, "diagonal", 0.0, 25.0, 2.0, needed=False)
    assert fast.utilisation > 1.0 > slow.utilisation
    at_needed = utilisation(cfg, "diagonal", 0.0, 25.0, fast.needed_scale, needed=False)
    assert at_needed.utilisation == pytest.approx(1.0, abs=0.02)


def test_a_payload_needs_more_time_a_higher_supply_less():
    cfg = load_config()
    capacity_25, capacity_40 = LegCapacity.of(cfg, 25e5), LegCapacity.of(cfg, 40e5)
    empty, loaded = (needed_scale(cfg, capacity_25, "circle", payload) for payload in (0.0, 3.0))
    assert loaded > empty and needed_scale(cfg, capacity_40, "circle", 3.0) < loaded


def test_a_force_beyond_what_the_leg_gives_at_its_speed_is_over_one():
    capacity = LegCapacity.of(load_config())
    at_rest = float(np.interp(0.0, capacity.velocities_m_s, capacity.push_n))
    ratios = capacity.utilisation(np.array([0.5 * at_rest, at_rest, 10.0, -10.0]), np.array([0.0, 0.0, 3.0, 0.0]))
    assert ratios[0] == pytest.approx(0.5) and ratios[1] == pytest.approx(1.0)
    assert math.isinf(ratios[2]) and 0.0 < ratios[3] < 0.1


def test_the_command_prints_the_table_and_refuses_a_bad_argument():
    out = hydrapod("design", "capacity", "--movements", "circle", "--payload-kg", "0", "--supply-bar", "40")
    assert out.returncode == 0 and "circle" in out.stdout and "needs time scale" in out.stdout
    bad = hydrapod("design", "capacity", "--supply-bar", "0")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
