"""The reference clock's rule holds its slowing `hold` cycles past the last trigger: a valve
that leaves its limit because the clock slowed does not bring the rate straight back (the rule
would chatter at half the cycle rate, a_r's y' r' term with it)."""

import numpy as np

from firmware_py.config import load_config
from firmware_py.motion_control.time_scaling import RATE_ONE, SPOOL_COUNTS, Clock, rule_of

PERIOD_S = 0.002


def _rates(clock: Clock, at_limit: list[bool]) -> list[int]:
    rates = []
    for limited in at_limit:
        clock.tick(np.full(6, 1.0 if limited else 0.1))
        rates.append(clock.rate)
    return rates


def test_one_cycle_at_the_limit_slows_the_clock_for_the_hold():
    rule = rule_of(load_config(), PERIOD_S)
    assert rule.hold == round(load_config().time_scaling.hold_s / PERIOD_S) > 1
    assert rule.spool_limit_counts <= SPOOL_COUNTS
    clock = Clock(rule, 6)
    clock.start(scaled=True)
    rates = _rates(clock, [True] + [False] * (2 * rule.hold))
    falling = np.diff([RATE_ONE] + rates)
    assert np.all(falling[:rule.hold] == -rule.slow)
    assert np.all(falling[rule.hold:] == rule.recover)


def test_a_trigger_on_every_other_cycle_slows_the_clock_steadily():
    rule = rule_of(load_config(), PERIOD_S)
    clock = Clock(rule, 6)
    clock.start(scaled=True)
    rates = _rates(clock, [k % 2 == 0 for k in range(40)])
    steps = np.diff([RATE_ONE] + rates)
    assert np.all(steps == -rule.slow), steps       # r' constant: a_r without a jump each cycle
