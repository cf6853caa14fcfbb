"""Report-only diagnostics of the fault monitors: how close each came to its threshold before
the run's first fault (the false-alarm margin a campaign reads from the summary). Nothing
here decides anything.

Each monitor's largest |r| / threshold per cycle is kept for DELAY cycles and counted only
once that old while no fault has latched: a fault's own rise (fewer cycles than DELAY)
never counts as a near miss.
"""

from __future__ import annotations

import numpy as np

DELAY = 64                             # cycles: a fault's residual rises over fewer than this before it latches
MONITORS = ("residual", "supply", "spool", "attitude", "pressure")
PEAK_KEYS = tuple(f"{name}_peak" for name in MONITORS)       # the summary's keys


class FalseAlarmMargins:
    def __init__(self):
        self.peak = np.zeros(len(MONITORS))        # the largest ratio counted, per monitor
        self._recent = np.zeros((DELAY, len(MONITORS)))

    def record(self, cycle: int, faulted: bool, residual: float, supply: float, spool: float, attitude: float,
               pressure: float) -> None:
        """One cycle's ratios; the one recorded DELAY cycles ago counts unless a fault latched."""
        slot = cycle % DELAY
        recent = self._recent[slot]
        if not faulted:
            np.maximum(self.peak, recent, out=self.peak)
        recent[0], recent[1], recent[2], recent[3], recent[4] = residual, supply, spool, attitude, pressure

    def as_dict(self) -> dict[str, float]:
        """`{monitor}_peak`: what the summary reports."""
        return {key: round(float(value), 3) for key, value in zip(PEAK_KEYS, self.peak)}
