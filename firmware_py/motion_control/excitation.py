"""The test bench's identification tests (HOST_TEST, chapter 6.4): the valve input of the
leg while one runs. Pure, scalar, allocation-free: the controller calls `output` once a cycle.

Experiment 1 (6.4.1.1, VALVE_STEP): a constant valve input, open loop, for DURATION: the
piston settles at a constant velocity, the steady-state friction map's data (eq. 6.4-6.5).
It ends early within `stroke_guard_m` of an end stop (the step would otherwise run into it).

Experiment 2 (6.4.2.1, FORCE_SINE): the piston force under proportional control about the
valve input that held the leg when it began (bumpless: the hold's force is the sine's
centre), u = u0 + K (F_ref - F_f), F_ref = F_p(start) + FORCE sin(2 pi t / DURATION), one
period: amplitudes below stiction move the piston within its pre-sliding range (eq.
6.8-6.12). F_p is eq. 6.5's piston force from the chamber pressures (LEG_PRESSURE, the
latest sample); F_f is F_p through a first-order low-pass far above the sine's frequency.
Fed the raw samples, the loop passes the sensors' noise to the valve and the piston jitters
below the displacement sensor's step: the bristles then move by far more than the record
shows, and no model fitted to the record can follow them.
"""

from __future__ import annotations

import math

from firmware_py.motion_control.estimation import first_order_gain
from protocol.enums import TestMode

TEST_MODES = frozenset(int(mode) for mode in TestMode)


class IdentificationSignal:
    def __init__(self, force_gain_v_n: float, force_filter_hz: float, stroke_guard_m: float, stroke_m: float,
                 saturation_v: float, period_s: float):
        self.force_gain_v_n, self.stroke_guard_m, self.stroke_m = force_gain_v_n, stroke_guard_m, stroke_m
        self.filter_gain = first_order_gain(period_s, force_filter_hz)     # F_f += a (F_p - F_f)
        self.saturation_v, self.period_s = saturation_v, period_s
        self.mode = TestMode.ABORT
        self.valve_v = 0.0
        self.force_n = 0.0
        self.duration_s = 0.0
        self.force0_n = 0.0
        self.force_filtered_n = 0.0
        self.u0_v = 0.0
        self.start_cycle = 0

    @property
    def running(self) -> bool:
        return self.mode != TestMode.ABORT

    def start(self, mode: int, valve_v: float, force_n: float, duration_s: float, cycle: int,
              piston_force: float, u0_v: float) -> None:
        self.mode, self.valve_v, self.force_n, self.duration_s = mode, valve_v, force_n, duration_s
        self.start_cycle, self.force0_n, self.u0_v = cycle, piston_force, u0_v
        self.force_filtered_n = piston_force

    def stop(self) -> None:
        self.mode = TestMode.ABORT

    def output(self, cycle: int, y_m: float, piston_force: float) -> tuple[float, bool]:
        """(valve input V, whether the test is over after this cycle)."""
        t = (cycle - self.start_cycle) * self.period_s
        done = t + self.period_s >= self.duration_s - 1e-9     # the last cycle of DURATION
        if self.mode == TestMode.VALVE_STEP:
            u = self.valve_v
            guard = self.stroke_guard_m
            if (u > 0.0 and y_m >= self.stroke_m - guard) or (u < 0.0 and y_m <= guard):
                return 0.0, True
        else:                                              # FORCE_SINE
            reference = self.force0_n + self.force_n * math.sin(2.0 * math.pi * t / self.duration_s)
            self.force_filtered_n += self.filter_gain * (piston_force - self.force_filtered_n)
            u = self.u0_v + self.force_gain_v_n * (reference - self.force_filtered_n)
        return min(max(u, -self.saturation_v), self.saturation_v), done
