"""The controlled stop after a fault isolated to one hexapod leg (beyond the thesis).

Locking all six legs where they are turns the faulty leg's error into a platform
displacement amplified by the near-vertical legs: a 1.5 mm error of one leg, locked, moved
the platform 18 mm sideways. So the faulty leg's valve holds at once (its load-holding
valves lock it) and for `cycles` the five others move to the pose nearest the commanded one
that agrees with the locked leg's length; then every valve holds.

Nearest in the platform's edge coordinates (translation, rotation times the anchor radius:
the Jacobian's scaled rows J_s): the least displacement dx with J_s[i] dx = delta, the
locked leg's length minus its reference, is dx = J_s[i] delta / |J_s[i]|^2, so leg j's
reference moves by (J_s[j] . J_s[i]) / |J_s[i]|^2 delta.
"""

from __future__ import annotations

import numpy as np


class ControlledStop:
    def __init__(self, n_legs: int, cycles: int):
        self.cycles = cycles
        self.leg = -1                           # the locked leg, -1: no stop under way
        self.left = 0
        self.base = np.zeros(n_legs)            # the references when the fault latched
        self.coupling = np.zeros(n_legs)        # leg j's share of the locked leg's error
        self.target = np.zeros(n_legs)
        self._delta = np.zeros(())              # 0-d: no conversion in the cycle

    @property
    def active(self) -> bool:
        return self.leg >= 0

    def begin(self, leg: int, reference_m: np.ndarray, jacobian_scaled: np.ndarray) -> None:
        """Start (an event): lock `leg`, the others from `reference_m`."""
        row = jacobian_scaled[leg]
        np.dot(jacobian_scaled, row, out=self.coupling)
        self.coupling /= float(np.dot(row, row))
        self.base[:] = reference_m
        self.leg, self.left = leg, self.cycles

    def step(self, position_m: np.ndarray) -> None:
        """This cycle's references from the locked leg's measured length; counts down."""
        self._delta[()] = position_m[self.leg] - self.base[self.leg]
        np.multiply(self.coupling, self._delta, out=self.target)
        self.target += self.base
        self.left -= 1
        if self.left <= 0:
            self.end()

    def end(self) -> None:
        self.leg, self.left = -1, 0
