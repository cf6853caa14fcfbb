"""Friction identification of chapter 6.4: the friction force from the equation of motion
(eq. 6.5), the bounded fit of the asymmetric steady-state map (eq. 6.4), and the pre-sliding
stiffness and damping (eq. 6.9, 6.12). Pure functions of arrays, SI (m, m/s, N).

Table 6.1 writes the negative side with negative alpha0, alpha1 and vs: F_ss(v) =
alpha0 + alpha1 exp(-(v/vs)^2) + sigma2 v on each side, the alphas carrying the side's sign.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from physics import lugre
from physics.constants import GRAVITY_M_S2


@dataclass(frozen=True)
class SteadySide:
    alpha0_n: float
    alpha1_n: float
    vs_m_s: float
    sigma2_ns_m: float

    def force(self, v_m_s: np.ndarray) -> np.ndarray:
        """Eq. 6.4."""
        v = np.asarray(v_m_s, float)
        return lugre.stribeck_curve(v, self.alpha0_n, self.alpha1_n, self.vs_m_s, 2.0) + self.sigma2_ns_m * v


def steady_sides(f: dict) -> dict[str, SteadySide]:
    """Both sides of eq. 6.4 from a section in Table 6.1's keys and units (the controller's and
    the emulator's [friction], the project's Table 6.1 copy)."""
    steady = slice(lugre.A0_POS, lugre.S2_NEG + 1)           # the steady-state set's keys, in SI
    values = [f[key] * scale for key, scale in zip(lugre.TABLE_KEYS[steady], lugre.TABLE_TO_SI[steady])]
    return {"+": SteadySide(*values[:4]), "-": SteadySide(*values[4:])}


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
    from scipy.optimize import least_squares
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
        return lugre.stribeck_curve(v, a0, a1, vs, 2.0) + s2 * v - f

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


# -- pre-sliding by the bristle model --------------------------------------------------------------
def displacement_from_crossings(cycle: np.ndarray, position_m: np.ndarray, n_cycles: int) -> np.ndarray:
    """The displacement at every cycle 0..n_cycles-1 from a quantised record (`position_m` at
    `cycle`, increasing): where the reading changes code, the true position crossed the boundary
    between the two codes between the two samples; straight lines through those crossings
    (and the record's ends). A reading that toggles across one boundary is then at rest on it,
    not moving by a whole step each time, which the bristle model would follow as motion."""
    change = np.flatnonzero(np.diff(position_m) != 0.0) + 1
    t = np.concatenate([cycle[:1], (cycle[change - 1] + cycle[change]) / 2.0, cycle[-1:]])
    y = np.concatenate([position_m[:1], (position_m[change - 1] + position_m[change]) / 2.0, position_m[-1:]])
    return np.interp(np.arange(n_cycles), t, y)


@numba.njit(cache=True)
def bristle_forces(dy_m, v_m_s, seal, guide_g, guide_k, z_seal0, z_guide0, seal_n, guide_n):
    """The bristle forces of the seal and of the guide along a measured displacement: the
    seal's LuGre state (eq. 6.2, `seal` a physics.lugre vector: g(v) of the side of motion,
    sigma0 by the sign of z as Table 6.2's two slopes) and the guide's (the same equation with
    its Coulomb level and one stiffness), each advanced exactly over every displacement
    increment dy at the velocity v of that cycle; seal_n[i] = sigma0 z_s, guide_n[i] = k_g z_g
    (eq. 6.1 at rest: the sigma1 and sigma2 terms vanish with v)."""
    z_s, z_g = z_seal0, z_guide0
    for i in range(dy_m.shape[0]):
        d, v = dy_m[i], v_m_s[i]
        g, _ = lugre.stribeck_side(d > 0.0, v, seal)
        sigma0, _ = lugre.bristle_coefficients(z_s, seal)
        z_s = lugre.bristle_relax(z_s, d, abs(g), sigma0)
        z_g = lugre.bristle_relax(z_g, d, guide_g, guide_k)
        sigma0, _ = lugre.bristle_coefficients(z_s, seal)
        seal_n[i] = sigma0 * z_s
        guide_n[i] = guide_k * z_g


def fit_presliding(dy_m: np.ndarray, v_m_s: np.ndarray, seal_at: np.ndarray, seal_friction_n: np.ndarray,
                   guide_at: np.ndarray, guide_friction_n: np.ndarray, steady: dict[str, SteadySide],
                   guide_coulomb_n: float, guess_n_m: float = 2e5) -> dict:
    """sigma0+, sigma0- of the seal and the guide's bristle stiffness by least squares: both
    bristle states simulated along the whole displacement record (`bristle_forces`), the
    seal's against the cylinder's friction measured at the indices `seal_at`, the guide's
    against the guide's at `guide_at` (the load cell between them tells the two apart), each
    with a constant offset (weight and mass errors) and its deflection at the record's start.
    `steady` gives the seal's g(v) (Table 6.1's map)."""
    from scipy.optimize import least_squares
    pos, neg = steady["+"], steady["-"]
    # the seal's law with the steady map given and sigma0 to be fitted (sigma1 plays no part at rest)
    seal = lugre.pack(pos.alpha0_n, pos.alpha1_n, pos.vs_m_s, pos.sigma2_ns_m, neg.alpha0_n, neg.alpha1_n,
                      neg.vs_m_s, neg.sigma2_ns_m, guess_n_m, 0.0, guess_n_m, 0.0)
    g_pos, g_neg = pos.alpha0_n + pos.alpha1_n, -(neg.alpha0_n + neg.alpha1_n)      # |g(0)| of each side
    seal_n, guide_n = np.empty(len(dy_m)), np.empty(len(dy_m))

    def model(q):
        s0p, s0n, kg = np.exp(q[:3])
        seal[lugre.S0_POS], seal[lugre.S0_NEG] = s0p, s0n
        # the initial deflections as fractions of their steady values (the record's start
        # state is unknown: after power-up, or after whatever moved the leg last)
        z_s0 = q[5] * (g_pos / s0p if q[5] >= 0 else g_neg / s0n)
        bristle_forces(dy_m, v_m_s, seal, guide_coulomb_n, kg, z_s0, q[6] * guide_coulomb_n / kg, seal_n, guide_n)
        return np.concatenate([seal_n[seal_at] + q[3] - seal_friction_n, guide_n[guide_at] + q[4] - guide_friction_n])

    q0 = np.array([np.log(guess_n_m), np.log(guess_n_m), np.log(guess_n_m / 2), 0.0, 0.0, 0.0, 0.0])
    lower = [np.log(1e3)] * 3 + [-np.inf, -np.inf, -1.0, -1.0]
    upper = [np.log(1e8)] * 3 + [np.inf, np.inf, 1.0, 1.0]
    result = least_squares(model, q0, bounds=(lower, upper), x_scale=[1.0, 1.0, 1.0, 10.0, 10.0, 0.5, 0.5])
    s0p, s0n, kg = np.exp(result.x[:3])
    seal_res, guide_res = result.fun[:len(seal_at)], result.fun[len(seal_at):]
    # standard errors of the three logs (relative errors of the stiffnesses); pinv: after a
    # move the initial deflections have no effect left, so their columns are zero
    jac = result.jac
    cov = np.linalg.pinv(jac.T @ jac) * np.mean(result.fun ** 2)
    rel = np.sqrt(np.abs(np.diag(cov)))[:3]
    return {"sigma0_pos_n_m": float(s0p), "sigma0_neg_n_m": float(s0n), "guide_n_m": float(kg),
            "offset_n": float(result.x[3]), "guide_offset_n": float(result.x[4]),
            "initial_deflection_fractions": [float(result.x[5]), float(result.x[6])],
            "rms_n": float(np.sqrt(np.mean(seal_res ** 2))), "guide_rms_n": float(np.sqrt(np.mean(guide_res ** 2))),
            "relative_std": [float(r) for r in rel], "points": len(seal_at), "guide_points": len(guide_at)}
