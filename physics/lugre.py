"""LuGre friction (eq. 6.1-6.4), asymmetric as Tables 6.1 and 6.2 identify it.

    F = sigma0 z + sigma1 dz/dt + sigma2 v                      (6.1)
    dz/dt = v - sigma0 |v| / |g(v)| z                           (6.2)
    g(v) = alpha0 + alpha1 exp(-|v / vs|^delta)                 (6.3), delta = 2
    F_ss(v) = g(v) + sigma2 v                                   (6.4)

The steady-state set (alpha0, alpha1, vs, sigma2) follows the sign of the velocity, the
negative side written with negative alphas as Table 6.1 does, so g is signed; the
pre-sliding set (sigma0, sigma1) follows the sign of the bristle deflection z (the two
slopes of Fig. 6.6). Both switch where their own term vanishes, so the force is continuous.
One parameter vector (`pack`) serves the controller's observer, the plant and the fits.

Eq. 6.2 is stiff (sigma0 |v| / |g| is thousands per second), so z is advanced exactly over
a displacement (`bristle_relax`): along a path dz/dx = sign(dx) - sigma0 z / |g|.
"""

from __future__ import annotations

import math
from functools import cached_property

import numba
import numpy as np

from physics.constants import MM
from program.sections import Section, frozen, key

# parameter vector, SI
A0_POS = 0      # alpha0+ [N]
A1_POS = 1      # alpha1+ [N]
VS_POS = 2      # vs+ [m/s]
S2_POS = 3      # sigma2+ [N s/m]
A0_NEG = 4      # alpha0- [N] (negative, as Table 6.1 writes it)
A1_NEG = 5      # alpha1- [N] (negative)
VS_NEG = 6      # vs- [m/s] (its sign is irrelevant: |v / vs|)
S2_NEG = 7      # sigma2- [N s/m]
S0_POS = 8      # sigma0 for z >= 0 [N/m]
S1_POS = 9      # sigma1 for z >= 0 [N s/m]
S0_NEG = 10     # sigma0 for z < 0 [N/m]
S1_NEG = 11     # sigma1 for z < 0 [N s/m]
DELTA = 12      # Stribeck exponent (2 in eq. 6.3; delta_s of the guide's eq. D.3)
SIZE = 13

def pack(alpha0_pos, alpha1_pos, vs_pos, sigma2_pos, alpha0_neg, alpha1_neg, vs_neg, sigma2_neg,
         sigma0_pos, sigma1_pos, sigma0_neg, sigma1_neg, delta=2.0) -> np.ndarray:
    """The parameter vector (SI); ValueError for parameters the law cannot use."""
    fp = np.array([alpha0_pos, alpha1_pos, vs_pos, sigma2_pos, alpha0_neg, alpha1_neg, vs_neg, sigma2_neg,
                   sigma0_pos, sigma1_pos, sigma0_neg, sigma1_neg, delta], dtype=float)
    if not (alpha0_pos + alpha1_pos > 0 and alpha0_neg + alpha1_neg < 0):
        raise ValueError("LuGre: g(0+) must be > 0 and g(0-) < 0 (Table 6.1 writes the - side negative)")
    if min(vs_pos, abs(vs_neg), sigma0_pos, sigma0_neg, delta) <= 0 or min(sigma1_pos, sigma1_neg, sigma2_pos,
                                                                            sigma2_neg) < 0:
        raise ValueError("LuGre: vs, sigma0 and delta must be > 0, sigma1 and sigma2 >= 0")
    return fp


@frozen
class LugreSection(Section):
    """A [friction] table: the seals' LuGre law in Table 6.1/6.2 units (both sides of the bus)."""
    alpha0_pos_n: float = key("alpha0_pos_n", -1000.0, 1000.0)
    alpha1_pos_n: float = key("alpha1_pos_n", -1000.0, 1000.0)
    vs_pos_m_s: float = key("vs_pos_mm_s", 0.01, 1e4, si=MM)
    sigma2_pos_ns_m: float = key("sigma2_pos_ns_mm", 0.0, 100.0, si=1.0 / MM)
    alpha0_neg_n: float = key("alpha0_neg_n", -1000.0, 1000.0)
    alpha1_neg_n: float = key("alpha1_neg_n", -1000.0, 1000.0)
    vs_neg_m_s: float = key("vs_neg_mm_s", -1e4, -0.01, si=MM)
    sigma2_neg_ns_m: float = key("sigma2_neg_ns_mm", 0.0, 100.0, si=1.0 / MM)
    sigma0_pos_n_m: float = key("sigma0_pos_n_mm", 1e-3, 1e6, si=1.0 / MM)
    sigma1_pos_ns_m: float = key("sigma1_pos_ns_mm", 0.0, 1e3, si=1.0 / MM)
    sigma0_neg_n_m: float = key("sigma0_neg_n_mm", 1e-3, 1e6, si=1.0 / MM)
    sigma1_neg_ns_m: float = key("sigma1_neg_ns_mm", 0.0, 1e3, si=1.0 / MM)

    def validate(self, where, error) -> None:
        try:
            _ = self.vector
        except ValueError as failure:
            raise error(f"{where}: {failure}") from None

    @cached_property
    def vector(self) -> np.ndarray:
        """The parameter vector (SI) the kernels take."""
        return pack(self.alpha0_pos_n, self.alpha1_pos_n, self.vs_pos_m_s, self.sigma2_pos_ns_m, self.alpha0_neg_n,
                    self.alpha1_neg_n, self.vs_neg_m_s, self.sigma2_neg_ns_m, self.sigma0_pos_n_m,
                    self.sigma1_pos_ns_m, self.sigma0_neg_n_m, self.sigma1_neg_ns_m)


# a [friction] table's keys in the vector's order (Table 6.1/6.2 units) and each one's factor to SI
TABLE_KEYS = tuple(LugreSection.keys())
TABLE_TO_SI = tuple(k.si for k in LugreSection.keys().values())


def from_table(section: dict) -> np.ndarray:
    """The vector from a [friction] table's values in Table 6.1/6.2 units (N, mm/s, N s/mm, N/mm)."""
    return pack(*(section[name] * scale for name, scale in zip(TABLE_KEYS, TABLE_TO_SI)))


@numba.njit(cache=True)
def stribeck_curve(v, alpha0, alpha1, vs, delta):
    """g(v) of eq. 6.3 for one side's parameters; v a number or an array."""
    return alpha0 + alpha1 * np.exp(-np.abs(v / vs) ** delta)


@numba.njit(cache=True)
def stribeck_side(positive, v, fp):
    """(signed g(v), sigma2) with the steady-state set of the given side."""
    if positive:
        return stribeck_curve(v, fp[A0_POS], fp[A1_POS], fp[VS_POS], fp[DELTA]), fp[S2_POS]
    return stribeck_curve(v, fp[A0_NEG], fp[A1_NEG], fp[VS_NEG], fp[DELTA]), fp[S2_NEG]


@numba.njit(cache=True)
def stribeck(v, fp):
    """(signed g(v), sigma2) for the side of v (v = 0 takes the + side)."""
    return stribeck_side(v >= 0.0, v, fp)


@numba.njit(cache=True)
def steady_friction(v, fp):
    """F_ss(v) = g(v) + sigma2 v (eq. 6.4); 0 at rest."""
    if v == 0.0:
        return 0.0
    g, sigma2 = stribeck(v, fp)
    return g + sigma2 * v


@numba.njit(cache=True)
def bristle_coefficients(z, fp):
    """(sigma0, sigma1) for the side of the bristle deflection z."""
    if z >= 0.0:
        return fp[S0_POS], fp[S1_POS]
    return fp[S0_NEG], fp[S1_NEG]


@numba.njit(cache=True)
def bristle_relax(z, displacement, g_abs, sigma0):
    """z after moving `displacement` with |g| held: the exact solution of eq. 6.2 along the
    path, relaxing toward its steady deflection sign(dx) |g| / sigma0."""
    if displacement == 0.0:
        return z
    z_ss = g_abs / sigma0 if displacement > 0.0 else -g_abs / sigma0
    return z_ss + (z - z_ss) * math.exp(-sigma0 * abs(displacement) / g_abs)


@numba.njit(cache=True)
def z_step(z, v, h, fp):
    """z after h seconds at velocity v (eq. 6.2, exact for v held)."""
    if v == 0.0:
        return z
    g, _ = stribeck(v, fp)
    sigma0, _ = bristle_coefficients(z, fp)
    return bristle_relax(z, v * h, abs(g), sigma0)


@numba.njit(cache=True)
def force_split(z, v, fp):
    """(sigma0 z, c) with F = sigma0 z + c v, c >= 0: eq. 6.1 with eq. 6.2 substituted,
    c = sigma1 (1 - sigma0 z sign(v) / |g|) + sigma2, so an integrator can take the
    velocity-proportional part implicitly."""
    sigma0, sigma1 = bristle_coefficients(z, fp)
    g, sigma2 = stribeck(v, fp)
    sign_v = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    damping = sigma1 * max(0.0, 1.0 - sigma0 * z * sign_v / abs(g)) + sigma2
    return sigma0 * z, damping
