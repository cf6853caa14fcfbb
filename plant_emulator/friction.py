"""LuGre friction (eq. 6.1-6.3), asymmetric, integrated stably; in place and allocation-free.

    F = sigma0 z + sigma1 dz/dt + sigma2 v                      (6.1)
    dz/dt = v - sigma0 |v| / |g(v)| z                           (6.2)
    g(v) = alpha0 + alpha1 exp(-|v / vs|^delta)                 (6.3), delta = 2

Asymmetry as identified in Tables 6.1/6.2: the steady-state set (alpha0, alpha1, vs, sigma2)
follows the sign of the velocity (the thesis writes the negative set with negative alphas,
so g is signed and F_ss(v) = g(v) + sigma2 v on both sides); the pre-sliding set (sigma0,
sigma1) follows the sign of the bristle deflection z, i.e. the slope of the
force-displacement chart on each side of Fig. 6.6. Both switch where their own term
vanishes (|v| = 0, z = 0), so the force stays continuous.

The same kernel serves the test bench's linear guide: eq. D.3's static map
F = Fc + (Fs - Fc) exp(-|v/vs|^delta_s) + sigma_v v is g(v) + sigma2 v with alpha0 = Fc,
alpha1 = Fs - Fc, delta = delta_s, symmetric, given bristles so that it sticks.

Stiffness: eq. 6.2 relaxes at sigma0 |v| / |g| (thousands per second) and sigma1 damps a
~0.2 kg rod at ~10^4 per second, both far beyond an explicit sub-step. So:
- z is advanced exactly for the step's velocity (exponential toward its steady value);
- the force is split as F = sigma0 z + c(v, z) v with c = sigma1 (1 - sigma0 z sign(v) / |g|)
  + sigma2 (an exact rewrite of sigma1 dz/dt + sigma2 v), and the integrators treat the
  damping c implicitly (the test bench solves for v; MuJoCo takes it as joint damping).
"""

from __future__ import annotations

import math

import numba
import numpy as np

FP_A0_POS = 0      # alpha0+ [N]
FP_A1_POS = 1      # alpha1+ [N]
FP_VS_POS = 2      # vs+ [m/s]
FP_S2_POS = 3      # sigma2+ [N s/m]
FP_A0_NEG = 4      # alpha0- [N] (negative, as Table 6.1 writes it)
FP_A1_NEG = 5
FP_VS_NEG = 6      # vs- [m/s] (its sign is irrelevant: |v/vs|)
FP_S2_NEG = 7
FP_S0_POS = 8      # sigma0 for z >= 0 [N/m]
FP_S1_POS = 9      # sigma1 for z >= 0 [N s/m]
FP_S0_NEG = 10
FP_S1_NEG = 11
FP_DELTA = 12      # Stribeck exponent (2 in eq. 6.3, delta_s in eq. D.3)
FP_SIZE = 13


@numba.njit(cache=True, inline="always")
def stribeck(v: float, fp: np.ndarray):
    """Signed g(v) of eq. 6.3 and sigma2 for the side of v (v = 0 takes the + side)."""
    if v >= 0.0:
        return fp[FP_A0_POS] + fp[FP_A1_POS] * math.exp(-abs(v / fp[FP_VS_POS]) ** fp[FP_DELTA]), fp[FP_S2_POS]
    return fp[FP_A0_NEG] + fp[FP_A1_NEG] * math.exp(-abs(v / fp[FP_VS_NEG]) ** fp[FP_DELTA]), fp[FP_S2_NEG]


@numba.njit(cache=True)
def steady_friction(v: float, fp: np.ndarray) -> float:
    """eq. 6.4: the friction at constant velocity v, F_ss = g(v) + sigma2 v."""
    g, sigma2 = stribeck(v, fp)
    if v == 0.0:
        return 0.0
    return g + sigma2 * v


@numba.njit(cache=True)
def lugre_split(z: float, v: float, fp: np.ndarray):
    """(sigma0 z, c) with F = sigma0 z + c v (eq. 6.1 with 6.2 substituted), c >= 0."""
    if z >= 0.0:
        sigma0, sigma1 = fp[FP_S0_POS], fp[FP_S1_POS]
    else:
        sigma0, sigma1 = fp[FP_S0_NEG], fp[FP_S1_NEG]
    g, sigma2 = stribeck(v, fp)
    sign_v = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    damping = sigma1 * max(0.0, 1.0 - sigma0 * z * sign_v / abs(g)) + sigma2
    return sigma0 * z, damping


@numba.njit(cache=True)
def lugre_z_step(z: float, v: float, h: float, fp: np.ndarray) -> float:
    """Exact solution of eq. 6.2 over h with v held: z relaxes to sign(v) |g| / sigma0."""
    if v == 0.0:
        return z
    sigma0 = fp[FP_S0_POS] if z >= 0.0 else fp[FP_S0_NEG]
    g, _ = stribeck(v, fp)
    g_abs = abs(g)
    z_ss = g_abs / sigma0 if v > 0.0 else -g_abs / sigma0
    return z_ss + (z - z_ss) * math.exp(-sigma0 * abs(v) / g_abs * h)


def pack_lugre(alpha0_pos, alpha1_pos, vs_pos, sigma2_pos, alpha0_neg, alpha1_neg, vs_neg, sigma2_neg,
               sigma0_pos, sigma1_pos, sigma0_neg, sigma1_neg, delta=2.0) -> np.ndarray:
    """The parameter vector of the kernels above, SI units."""
    fp = np.empty(FP_SIZE)
    fp[:] = (alpha0_pos, alpha1_pos, vs_pos, sigma2_pos, alpha0_neg, alpha1_neg, vs_neg, sigma2_neg,
             sigma0_pos, sigma1_pos, sigma0_neg, sigma1_neg, delta)
    if not (alpha0_pos + alpha1_pos > 0 and alpha0_neg + alpha1_neg < 0):
        raise ValueError("LuGre: g(0+) must be > 0 and g(0-) < 0 (Table 6.1 writes the - side negative)")
    if min(vs_pos, abs(vs_neg), sigma0_pos, sigma0_neg) <= 0 or min(sigma1_pos, sigma1_neg, sigma2_pos,
                                                                     sigma2_neg) < 0:
        raise ValueError("LuGre: vs, sigma0 must be > 0 and sigma1, sigma2 >= 0")
    return fp
