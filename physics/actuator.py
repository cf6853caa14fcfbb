"""The asymmetric cylinder: its areas and hydraulic force (eq. 4.15, 4.24, 6.5), and the
declarations of the keys both sides of the bus read of a leg (the cylinder, its valve's
input, its transducers, the payload)."""

from __future__ import annotations

import math
from functools import cached_property

import numba

from physics.constants import BAR, MM
from program.sections import Key, Section, frozen, key

BORE_RADIUS = Key("bore_radius_mm", 0.5, 100.0, MM)
ROD_RADIUS = Key("rod_radius_mm", 0.1, 99.0, MM)
STROKE = Key("stroke_mm", 10.0, 2000.0, MM)
VALVE_FULL_SCALE = Key("valve_full_scale_v", 0.01, 24.0)           # the valve input at 100 % spool
ENCODER_RESOLUTION = Key("encoder_resolution_mm", 1e-4, 10.0, MM)
LOAD_CELL_NOISE = Key("load_cell_noise_n", 0.0, 100.0)             # 1-sigma
PRESSURE_NOISE = Key("pressure_noise_bar", 0.0, 10.0, BAR)         # 1-sigma of a chamber transducer
PAYLOAD = Key("payload_kg", 0.0, 100.0)                            # on the platform, at its centre of mass
# the test bench's linear guide (Appendix D): its slide, and eq. D.3's friction at gross motion
SLIDE_MASS = Key("slide_mass_kg", 0.01, 100.0)
GUIDE_COULOMB = Key("coulomb_n", 0.0, 1000.0)
GUIDE_VISCOUS = Key("viscous_ns_mm", 0.0, 100.0, per=MM)


def cylinder_areas(bore_radius_m: float, rod_radius_m: float) -> tuple[float, float]:
    """(A_A, alpha): the piston area and the annulus-to-piston area ratio A_B / A_A."""
    if not 0.0 < rod_radius_m < bore_radius_m:
        raise ValueError(f"rod radius {rod_radius_m} m must be positive and below the bore radius {bore_radius_m} m")
    return math.pi * bore_radius_m ** 2, 1.0 - (rod_radius_m / bore_radius_m) ** 2


@numba.njit(cache=True, inline="always")
def piston_force(pa_pa, pb_pa, area_m2, alpha):
    """F_p = A_A (p_A - alpha p_B), positive extending (eq. 4.15, 6.5)."""
    return area_m2 * (pa_pa - alpha * pb_pa)


@frozen
class CylinderSection(Section):
    """The keys of an [actuator] table that set the cylinder (both sides of the bus)."""
    bore_radius_m: float = key(BORE_RADIUS)
    rod_radius_m: float = key(ROD_RADIUS)
    stroke_m: float = key(STROKE)

    def validate(self, where, error) -> None:
        if self.rod_radius_m >= self.bore_radius_m:
            raise error(f"{where}.rod_radius_mm = {round(self.rod_radius_m / MM, 9)} must be smaller than "
                        f"bore_radius_mm = {round(self.bore_radius_m / MM, 9)}")

    @cached_property
    def piston_area_m2(self) -> float:
        """A_A, the bore: the load pressure pA - alpha pB acts on it."""
        return cylinder_areas(self.bore_radius_m, self.rod_radius_m)[0]

    @cached_property
    def area_ratio(self) -> float:
        """alpha = A_B / A_A."""
        return cylinder_areas(self.bore_radius_m, self.rod_radius_m)[1]
