"""The asymmetric cylinder's areas and its hydraulic force (eq. 4.15, 4.24, 6.5)."""

from __future__ import annotations

import math

import numba


def cylinder_areas(bore_radius_m: float, rod_radius_m: float) -> tuple[float, float]:
    """(A_A, alpha): the piston area and the annulus-to-piston area ratio A_B / A_A."""
    if not 0.0 < rod_radius_m < bore_radius_m:
        raise ValueError(f"rod radius {rod_radius_m} m must be positive and below the bore radius {bore_radius_m} m")
    return math.pi * bore_radius_m ** 2, 1.0 - (rod_radius_m / bore_radius_m) ** 2


@numba.njit(cache=True, inline="always")
def piston_force(pa_pa, pb_pa, area_m2, alpha):
    """F_p = A_A (p_A - alpha p_B), positive extending (eq. 4.15, 6.5)."""
    return area_m2 * (pa_pa - alpha * pb_pa)
