"""The fault matrix's transient comparison: what a fault changed, not where the probes began."""

import numpy as np

from hil.faults.judge import _largest_change


def test_the_offset_before_the_injection_is_not_the_faults():
    diff = np.full((5, 6), 0.5e-3)                  # two probes 0.5 mm apart from rest
    diff[3, 2] += 0.2e-3                            # the fault moved leg 3 by 0.2 mm
    assert abs(_largest_change(diff, np.abs) - 0.2e-3) < 1e-12


def test_cycles_without_the_faulted_legs_frame_are_skipped_but_the_reference_must_be_whole():
    diff = np.zeros((4, 6))
    diff[1, 0] = np.nan
    diff[2, 4] = -0.3e-3
    assert abs(_largest_change(diff, np.abs) - 0.3e-3) < 1e-12
    diff[0, 1] = np.nan
    assert _largest_change(diff, np.abs) is None


def test_the_platform_change_is_a_distance():
    diff = np.zeros((3, 3))
    diff[2] = (3e-3, 4e-3, 0.0)
    assert abs(_largest_change(diff, lambda d: np.linalg.norm(d, axis=1)) - 5e-3) < 1e-12
