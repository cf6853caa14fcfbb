"""Appendix D: the linear guide's friction from free falls of its slide (pure computation on
arrays; the scenario cuts the falls out of a log).

A fall: the slide (mass m = slide + external load) released at rest at t_r, falling a
distance s (positive down) under its weight and the guide's friction F(v), eq. D.1:
m s'' = m g - F(s'). Two ways to F:

- the thesis's (eq. D.2): F = m (g - s'') sample by sample, s' and s'' by finite differences
  behind a 4th-order Butterworth low-pass (100 Hz): Fig. D.1's cloud;
- output error on the encoder's record: the fall eq. D.4 (F = Fc + sigma_v v) predicts in
  closed form (`fall_d4`), fitted with the release time per fall and Fc, sigma_v common to
  all falls (Table D.1 gives one Fc and one sigma_v for every load); then eq. D.3's Stribeck
  part (Fs, vs per load, delta_s held) by integrating it, with Fc, sigma_v from the first fit.
  No derivative of the 0.125 mm encoder: eq. D.2's s'' carries its counts as ~4 m/s^2 of
  noise at 100 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.identification import fit_index
from physics.constants import GRAVITY_M_S2

INTEGRATION_STEP_S = 2.5e-4      # eq. D.3's fall integrated at this step (the record's 2 ms / 8)


@dataclass
class Fall:
    """One fall's record: t from the valve step that let it go, s fallen (m, down positive)."""
    load_kg: float
    mass_kg: float
    t_s: np.ndarray
    s_m: np.ndarray


def fall_d4(t_s: np.ndarray, release_s: float, mass_kg: float, coulomb_n: float, viscous_ns_m: float) -> np.ndarray:
    """The distance fallen under eq. D.4 from rest at `release_s` (0 before it):
    s = a0 / k (tau - (1 - exp(-k tau)) / k), a0 = g - Fc / m, k = sigma_v / m."""
    tau = np.maximum(t_s - release_s, 0.0)
    a0 = max(GRAVITY_M_S2 - coulomb_n / mass_kg, 0.0)     # below its breakaway the slide stays
    k = viscous_ns_m / mass_kg
    if k * float(np.max(tau, initial=0.0)) < 1e-6:
        return 0.5 * a0 * tau ** 2
    return a0 / k * (tau - (1.0 - np.exp(-k * tau)) / k)


def stribeck_friction(v_m_s: float, coulomb_n: float, static_n: float, stribeck_m_s: float, exponent: float,
                      viscous_ns_m: float) -> float:
    """Eq. D.3 for v >= 0."""
    return coulomb_n + (static_n - coulomb_n) * math.exp(-abs(v_m_s / stribeck_m_s) ** exponent) + viscous_ns_m * v_m_s


def fall_d3(t_s: np.ndarray, release_s: float, mass_kg: float, coulomb_n: float, viscous_ns_m: float,
            static_n: float, stribeck_m_s: float, exponent: float) -> np.ndarray:
    """The distance fallen under eq. D.3 from rest at `release_s`, integrated (Euler on v, the
    trapezoid on s, at INTEGRATION_STEP_S), sampled at `t_s`. A static friction at or above the weight
    holds the slide."""
    end = float(np.max(t_s)) - release_s
    if end <= 0.0 or static_n >= mass_kg * GRAVITY_M_S2:
        return np.zeros_like(t_s)
    n = int(math.ceil(end / INTEGRATION_STEP_S)) + 1
    h, v, s = INTEGRATION_STEP_S, 0.0, 0.0
    track = np.empty(n + 1)
    track[0] = 0.0
    for i in range(n):
        friction = stribeck_friction(v, coulomb_n, static_n, stribeck_m_s, exponent, viscous_ns_m)
        v_new = max(v + h * (GRAVITY_M_S2 - friction / mass_kg), 0.0)
        s += 0.5 * h * (v + v_new)
        v = v_new
        track[i + 1] = s
    return np.interp(t_s - release_s, np.arange(n + 1) * h, track, left=0.0)


def fit_viscous(falls: list[Fall], guess=(10.0, 10.0)) -> dict:
    """Eq. D.4's Fc [N], sigma_v [N s/m] common to every fall, each fall's release time;
    least squares on the distance fallen. Each fall's fit index (eq. 5.12) with them."""
    from scipy.optimize import least_squares

    releases = [float(f.t_s[np.argmax(f.s_m > 0.0)]) if np.any(f.s_m > 0.0) else 0.0 for f in falls]

    def residuals(q):
        fc, sv = q[0], q[1]
        return np.concatenate([fall_d4(f.t_s, q[2 + i], f.mass_kg, fc, sv) - f.s_m for i, f in enumerate(falls)])

    lower = [0.0, 0.0] + [float(f.t_s[0]) - 0.05 for f in falls]
    upper = [np.inf, np.inf] + [float(f.t_s[-1]) for f in falls]
    start = np.clip([*guess, *releases], lower, np.array(upper) - 1e-9)
    result = least_squares(residuals, start, bounds=(lower, upper), x_scale=[1.0, 1.0] + [0.01] * len(falls))
    fc, sv = float(result.x[0]), float(result.x[1])
    fits = [fit_index(f.s_m, fall_d4(f.t_s, result.x[2 + i], f.mass_kg, fc, sv)) for i, f in enumerate(falls)]
    return {"coulomb_n": fc, "viscous_ns_m": sv, "release_s": [float(r) for r in result.x[2:]], "fit": fits}


def fit_stribeck(falls: list[Fall], releases: list[float], coulomb_n: float, viscous_ns_m: float,
                 exponent: float, stribeck_guess_m_s: float = 0.3) -> dict:
    """Eq. D.3's Fs [N] and vs [m/s] for the falls of one load, Fc and sigma_v held (and the
    release times of `fit_viscous`); `identifiable` is False where Fs - Fc stays within the
    fit's own uncertainty (then the fall is eq. D.4's and vs means nothing)."""
    from scipy.optimize import least_squares

    weight = falls[0].mass_kg * GRAVITY_M_S2

    def residuals(q):
        excess, vs = q
        return np.concatenate([fall_d3(f.t_s, r, f.mass_kg, coulomb_n, viscous_ns_m, coulomb_n + excess, vs,
                                       exponent) - f.s_m for f, r in zip(falls, releases)])

    room = max(weight - coulomb_n - 1e-3, 1e-3)
    result = least_squares(residuals, [min(0.2 * room, 2.0), stribeck_guess_m_s],
                           bounds=([0.0, 1e-3], [room, 5.0]), x_scale=[1.0, 0.1])
    excess, vs = (float(x) for x in result.x)
    # 1-sigma of the excess from the Jacobian and the residuals' spread
    dof = max(len(result.fun) - 2, 1)
    spread = float(np.sqrt(np.sum(result.fun ** 2) / dof))
    try:
        cov = np.linalg.inv(result.jac.T @ result.jac) * spread ** 2
        sigma = float(np.sqrt(max(cov[0, 0], 0.0)))
    except np.linalg.LinAlgError:
        sigma = math.inf
    return {"static_n": coulomb_n + excess, "stribeck_m_s": vs, "excess_sigma_n": sigma,
            "identifiable": excess > 3.0 * sigma and excess > 0.05 * coulomb_n}


def friction_d2(s_m: np.ndarray, mass_kg: float, period_s: float, cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. D.2 as the thesis computed it: (v [m/s], F = m (g - s'') [N]) from backward
    differences behind a causal 4th-order Butterworth (as a real-time board runs it, from
    rest): at the release s'' is still 0, so F starts at the weight."""
    from scipy import signal
    sos = signal.butter(4, cutoff_hz, fs=1.0 / period_s, output="sos")
    sf, _ = signal.sosfilt(sos, s_m, zi=signal.sosfilt_zi(sos) * s_m[0])
    v = np.diff(sf, prepend=sf[0]) / period_s
    return v, mass_kg * (GRAVITY_M_S2 - np.diff(v, prepend=v[0]) / period_s)
