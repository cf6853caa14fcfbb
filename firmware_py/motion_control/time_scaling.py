"""Online time scaling: the reference's clock slows while the actuators cannot follow it.

A trajectory is a path y(tau) and a clock tau. At full speed tau advances one period per
cycle; while a valve's command sits at its limit or the supply the valves share has fallen
below its share of the set pressure (flow running short), the clock's rate r falls, and it
climbs back to 1 when neither holds. The path is the host's; only its timing stretches:
    y_r = y(tau),  v_r = y'(tau) r,  a_r = y''(tau) r^2 + y'(tau) r'      (r' = dr/dt)
so computed torque's feedforward stays consistent with the reference it follows.

The rate and the clock are integers (RATE_ONE ticks per cycle at full speed) and the triggers
are the frames on the bus (VALVE_CMD's setpoint counts, LEG_PRESSURE's PS), so a log's
analysis replays the very same clock (hil/reference_rebuild.py); CTRL_CLOCK carries it every
48th SYNC. At full rate tau = (cycles since the start) T, the rule the rest of the project
already follows. Steps (a held setpoint) are not scaled: they have no speed to lower.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from protocol.dbc import signal_scale

RATE_ONE = 1024                   # clock ticks per cycle at full speed
# VALVE_CMD's setpoint counts at full opening (the DBC's % step; CiA 408 0x6311's 16384)
SPOOL_COUNTS = round(100.0 / signal_scale("VALVE_CMD_1", "SPOOL_SETPOINT"))


@dataclass(frozen=True)
class ScalingRule:
    """The rule's parameters, in ticks per cycle (from [time_scaling], `rule_of`)."""
    enabled: bool
    rate_min: int                 # the slowest the clock runs, ticks per cycle
    slow: int                     # the rate's fall per cycle while a trigger holds
    recover: int                  # its rise per cycle otherwise
    spool_limit_counts: int       # a command at or beyond this many counts is at its limit
    supply_low_pa: float          # any valve's latest P-port sample below this: flow runs short
    hold: int = 1                 # the rate keeps falling this many cycles from the last trigger


def rule_of(cfg, period_s: float) -> ScalingRule:
    """The rule from a controller configuration."""
    ts = cfg.time_scaling
    return ScalingRule(ts.enabled, max(int(round(ts.rate_min * RATE_ONE)), 1),
                       max(int(round(ts.slow_per_s * period_s * RATE_ONE)), 1),
                       max(int(round(ts.recover_per_s * period_s * RATE_ONE)), 1),
                       int(round(cfg.limits.spool_max * SPOOL_COUNTS)),
                       cfg.waypoints.supply_share * cfg.hydraulic_model.supply_pressure_pa,
                       max(int(round(ts.hold_s / period_s)), 1))


@njit(cache=True)
def spool_at_limit(spool, limit_counts) -> bool:
    """Any valve's setpoint (fraction of full opening) at its limit, in VALVE_CMD's counts."""
    for u in spool:
        if abs(round(u * SPOOL_COUNTS)) >= limit_counts:
            return True
    return False


@njit(cache=True)
def supply_update(ps_pa, fresh, latest) -> None:
    """Each valve's latest P-port sample (`latest`, NaN before any) from this cycle's fresh ones."""
    for i in range(ps_pa.shape[0]):
        if fresh[i]:
            latest[i] = ps_pa[i]


@njit(cache=True)
def rate_step(rate, holding, latest_pa, spool_sent, supply_low_pa, limit_counts, rate_min, slow, recover,
              hold) -> tuple[int, int]:
    """(this cycle's rate, the cycles it still keeps falling) from the last one's: lower while
    any valve's command is at its limit or any valve's supply below `supply_low_pa` and for
    `hold` cycles after, else back towards full speed. Without the hold the rule chatters at
    half the cycle rate: the slowing lowers a_r's y' r' term, the valve leaves its limit, the
    rate climbs, a_r jumps back and the valve is at its limit again."""
    triggered = spool_at_limit(spool_sent, limit_counts)
    for p in latest_pa:
        triggered = triggered or p < supply_low_pa
    holding = hold if triggered else max(holding - 1, 0)
    if holding > 0:
        return max(rate - slow, rate_min), holding
    return min(rate + recover, RATE_ONE), holding


@njit(cache=True)
def scale_derivatives(velocity, acceleration, rate, rate_per_s) -> None:
    """In place: dy/dtau, d2y/dtau2 to dy/dt = y' r and d2y/dt2 = y'' r^2 + y' r'."""
    for j in range(velocity.shape[0]):
        acceleration[j] = acceleration[j] * rate * rate + velocity[j] * rate_per_s
        velocity[j] *= rate


class Clock:
    """A trajectory's clock under the rule: `start()` with the trajectory, `tick()` once per
    cycle it is advanced. Allocation-free."""

    def __init__(self, rule: ScalingRule, n_legs: int):
        self.rule = rule
        self.latest_pa = np.full(n_legs, np.nan)
        self.rate = RATE_ONE
        self.previous_rate = RATE_ONE
        self.holding = 0          # cycles the rate keeps falling (`rate_step`)
        self.ticks = 0
        self.scaling = False      # the running trajectory is one the rule scales

    def start(self, scaled: bool) -> None:
        self.rate = self.previous_rate = RATE_ONE
        self.holding = 0
        self.ticks = 0
        self.scaling = scaled and self.rule.enabled

    def warm_up(self, spool) -> None:
        """Compile the cycle's kernels (numba) before the first cycle needs them."""
        r = self.rule
        rate_step(RATE_ONE, 0, self.latest_pa, spool, r.supply_low_pa, r.spool_limit_counts, r.rate_min, r.slow,
                  r.recover, r.hold)
        scale_derivatives(self.latest_pa.copy(), self.latest_pa.copy(), 1.0, 0.0)
        supply_update(self.latest_pa.copy(), np.zeros(len(self.latest_pa), dtype=np.bool_), self.latest_pa.copy())

    def observe(self, ps_pa, fresh) -> None:
        """Every cycle: the valves' P-port samples."""
        supply_update(ps_pa, fresh, self.latest_pa)

    def tick(self, spool_sent) -> None:
        """The clock's advance this cycle, `spool_sent` the commands of the last one."""
        self.previous_rate = self.rate
        if self.scaling:
            r = self.rule
            self.rate, self.holding = rate_step(self.rate, self.holding, self.latest_pa, spool_sent, r.supply_low_pa,
                                                r.spool_limit_counts, r.rate_min, r.slow, r.recover, r.hold)
        self.ticks += self.rate

    def cycles(self) -> float:
        """The clock, in cycles of full speed."""
        return self.ticks / RATE_ONE

    @property
    def rate_fraction(self) -> float:
        return self.rate / RATE_ONE

    def scale(self, velocity, acceleration, period_s: float) -> None:
        """The path's derivatives in tau (as evaluated) to the reference's in time."""
        if self.rate != RATE_ONE or self.previous_rate != RATE_ONE:
            scale_derivatives(velocity, acceleration, self.rate / RATE_ONE,
                              (self.rate - self.previous_rate) / RATE_ONE / period_s)


DISABLED = ScalingRule(False, RATE_ONE, 1, 1, SPOOL_COUNTS, 0.0)
