"""LogView's reading of the emulator's truth after a fault: what is left of the platform's
swing (the fault matrix's rest criterion)."""

import numpy as np

from hil.logquery import LogView


def _view(truth_m: np.ndarray, cycles: np.ndarray) -> LogView:
    view = object.__new__(LogView)           # the truth arrays alone, without a log behind them
    view.period_s, view.truth, view.truth_cycle = 0.002, truth_m, cycles
    return view


def test_the_swing_left_is_the_largest_distance_from_where_the_platform_stands():
    t = np.arange(1000) * 0.002
    x = 0.020 * np.exp(-t / 0.5) * np.sin(2 * np.pi * 1.3 * t)          # a 1.3 Hz swing decaying
    truth = np.column_stack([x, np.zeros_like(x), np.full_like(x, 0.6)])
    view = _view(truth, np.arange(1000))
    early, late = view.swing_after(0, 0.0, 0.4), view.swing_after(0, 1.2, 0.4)
    assert late < 0.005 < early < 0.020
    still = _view(np.tile([0.0, 0.0, 0.6], (1000, 1)), np.arange(1000))
    assert still.swing_after(100, 0.5, 0.4) < 1e-12


def test_no_swing_is_read_where_the_truth_is_missing():
    truth = np.tile([0.0, 0.0, 0.6], (1000, 1))
    view = _view(truth, np.arange(1000))
    assert view.swing_after(None, 0.5, 0.4) is None
    assert view.swing_after(900, 0.5, 0.4) is None                      # beyond the log's end
    gappy = _view(truth[::2], np.arange(0, 1000, 2))                     # half the cycles
    assert gappy.swing_after(0, 0.5, 0.4) is None
