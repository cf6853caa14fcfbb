"""Friction identification of chapter 6.4: the friction force from the equation of motion
(eq. 6.5), the bounded fit of the asymmetric steady-state map (eq. 6.4), and the pre-sliding
stiffness and damping (eq. 6.9, 6.12). Pure functions of arrays, SI (m, m/s, N).

Table 6.1 writes the negative side with negative alpha0, alpha1 and vs: F_ss(v) =
alpha0 + alpha1 exp(-(v/vs)^2) + sigma2 v on each side, the alphas carrying the side's sign.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from firmware_py.geometry import GRAVITY_M_S2


@dataclass(frozen=True)
class SteadySide:
    alpha0_n: float
    alpha1_n: float
    vs_m_s: float
    sigma2_ns_m: float

    def force(self, v_m_s: np.ndarray) -> np.ndarray:
        """Eq. 6.4."""
        v = np.asarray(v_m_s, float)
        return self.alpha0_n + self.alpha1_n * np.exp(-(v / self.vs_m_s) ** 2) + self.sigma2_ns_m * v


def cylinder_friction(piston_force_n, accel_m_s2, velocity_m_s, moving_mass_kg: float, guide_coulomb_n: float,
                      guide_viscous_ns_m: float):
    """Eq. 6.5: Ff = Fp - mT a - mT g - Ffg(v), the guide's friction Ffg = Fc sign(v) + sigma_v v
    (Table D.1's gross-motion map), the piston extending upward against gravity."""
    v = np.asarray(velocity_m_s, float)
    guide = guide_coulomb_n * np.sign(v) + guide_viscous_ns_m * v
    return (np.asarray(piston_force_n, float) - moving_mass_kg * np.asarray(accel_m_s2, float)
            - moving_mass_kg * GRAVITY_M_S2 - guide)


def fit_steady_side(v_m_s: np.ndarray, f_n: np.ndarray, sign: float) -> tuple[SteadySide, dict]:
    """Eq. 6.4 on one side (sign +1: v > 0, -1: v < 0) by bounded nonlinear least squares
    (the thesis: lsqcurvefit with bounds from the observed extremes). Returns the parameters
    with the side's sign on alpha0, alpha1 and vs (Table 6.1's convention) and fit figures."""
    v, f = np.asarray(v_m_s, float), np.asarray(f_n, float)
    keep = np.sign(v) == sign
    v, f = sign * v[keep], sign * f[keep]                 # mirrored onto the positive side
    if len(v) < 4:
        raise ValueError(f"{len(v)} points on the {'+' if sign > 0 else '-'} side; the fit needs >= 4")
    f_max, v_max, v_min = float(np.max(np.abs(f))), float(v.max()), float(v.min())
    lower = [0.0, 0.0, max(0.25 * v_min, 1e-5), 0.0]
    upper = [f_max, f_max, v_max, 2.0 * f_max / v_max]
    slow = v <= np.median(v)
    guess = np.clip([float(np.min(f)), max(float(np.max(f[slow]) - np.min(f)), 0.1), float(np.median(v)) / 2,
                     max(float(np.polyfit(v, f, 1)[0]), 0.0)], np.add(lower, 1e-9), np.subtract(upper, 1e-9))

    def residual(q):
        a0, a1, vs, s2 = q
        return a0 + a1 * np.exp(-(v / vs) ** 2) + s2 * v - f

    result = least_squares(residual, guess, bounds=(lower, upper), x_scale=[f_max, f_max, v_max, f_max / v_max])
    a0, a1, vs, s2 = result.x
    rms = float(np.sqrt(np.mean(result.fun ** 2)))
    return (SteadySide(sign * a0, sign * a1, sign * vs, s2),
            {"points": len(v), "rms_n": rms, "at_bound": [bool(np.isclose(x, lo) or np.isclose(x, hi))
                                                             for x, lo, hi in zip(result.x, lower, upper)]})


def presliding_stiffness(displacement_m: np.ndarray, friction_n: np.ndarray) -> float:
    """Eq. 6.9, Ff ~ sigma0 y: the slope through the origin of the force-displacement chart
    (least squares), on the points given (one side of it)."""
    d, f = np.asarray(displacement_m, float), np.asarray(friction_n, float)
    return float(np.dot(d, f) / np.dot(d, d))


def presliding_damping(sigma0_n_m: float, mass_kg: float, sigma2_ns_m: float, zeta: float = 1.0) -> float:
    """Eq. 6.12: sigma1 = 2 zeta sqrt(sigma0 mT) - sigma2 (eq. 6.11 critically damped at zeta = 1)."""
    return 2.0 * zeta * np.sqrt(sigma0_n_m * mass_kg) - sigma2_ns_m
