"""Chapter 5.2: identification of the servo-hydraulic actuator from closed-loop P-control
transients (pure computation on arrays; the scenario cuts the windows out of a log).

Per transient window (150 ms after each change of the PRMS reference, chapter 5.4.1):
1. the proportional gain K from the logged valve input, u = K (yr - y) + u0 (least squares:
   the analysis needs nothing but the log);
2. the closed-loop model Gcl(s) = n0 / (s^3 + a2 s^2 + a1 s + a0) fitted to the step of the
   reference (output error, the loop's one-period command latency as a known delay), in
   the structure of a type-I plant under P control (a0 = n0: the pole correction of
   chapter 5.4.1 built in);
3. the open-loop model by eq. 5.5, Gol = (1/K) n0 / (s^3 + a2 s^2 + a1 s + a0 - n0): its
   complex pair gives b0 = |p|^2, b1 = -2 Re p, and k01 = n0 / (K b0);
4. m, sigma, Fe by least squares on A PL = m y'' + sigma y' + Fe (eq. 5.6-5.7), with y' and
   y'' from a zero-phase low-pass of the encoder and the same filter on PL;
5. the sensibility constants Kx, Kd, Kp of PL' = Kx xv - Kd y' + Kp PL (eq. 4.50) from G(s),
   m and sigma (eq. 5.8-5.10), and back from them the complete model of eq. 5.11 with the
   load's path; and, beside them, Kx, Kd, Kp by least squares on eq. 4.50 itself from the
   logged chamber pressures (`load_pressure_fit`).
Fit index eq. 5.12: F = 1 - |y - ys| / |y - mean(y)|.
6. the scheduled model of Fig. 5.10: G(s)'s b0, b1, k01 of every working point in a table
   over the set point, per load, read between the points by spline interpolation (as the
   thesis's 2-D table does); `scheduled_parameter` reads it, `leave_one_out` judges it at a
   point the table was made without.
"""

from __future__ import annotations

import numpy as np


def proportional_gain(u_v: np.ndarray, error_m: np.ndarray) -> tuple[float, float]:
    """K [V/m] and u0 [V] of u = K e + u0 (least squares over the window)."""
    ok = np.isfinite(u_v) & np.isfinite(error_m)
    a = np.column_stack([error_m[ok], np.ones(ok.sum())])
    (k, u0), *_ = np.linalg.lstsq(a, u_v[ok], rcond=None)
    return float(k), float(u0)


def lti_response(num, den, u: np.ndarray, dt_s: float) -> np.ndarray:
    """The response of the strictly proper num(s) / den(s), at rest at the first sample, to `u`
    sampled `dt_s` apart and linear between its samples: `scipy.signal.lsim`'s (its default
    first-order hold, the same discretisation), as a convolution. lsim converts the system and
    steps its state in Python each call: the refinement calls this ~10^4 times."""
    from scipy.linalg import expm
    den = np.asarray(den, dtype=float)
    n = len(den) - 1
    c = np.zeros(n)
    c[n - len(num):] = np.asarray(num, dtype=float) / den[0]
    a = np.zeros((n, n))                            # controllable canonical form
    a[0] = -den[1:] / den[0]
    a[1:, :-1] = np.eye(n - 1)
    # x(k+1) = Ad x(k) + B0 u(k) + B1 u(k+1) over an input linear between samples
    m = np.zeros((n + 2, n + 2))
    m[:n, :n], m[0, n], m[n, n + 1] = a * dt_s, dt_s, 1.0
    e = expm(m)
    ad, b1 = e[:n, :n], e[:n, n + 1]
    b0 = e[:n, n] - b1
    samples = len(u)
    # C Ad^k B0 and C Ad^k B1 for every k: through Ad's eigenvalues where they are distinct
    # (the poles'), else by its powers
    z, v = np.linalg.eig(ad)
    if np.linalg.cond(v) < 1e8:
        left, powers = c @ v, np.power.outer(z, np.arange(samples))
        h0, h1 = (np.real((left * np.linalg.solve(v, b)) @ powers) for b in (b0, b1))
    else:
        h0, h1, row = np.empty(samples), np.empty(samples), c.copy()
        for k in range(samples):
            h0[k], h1[k] = row @ b0, row @ b1
            row = row @ ad
    u = np.asarray(u, dtype=float)
    out = np.zeros(samples)
    out[1:] = (np.convolve(h0, u)[:samples - 1] + np.convolve(h1, u[1:])[:samples - 1])
    return out


def closed_loop_step(n0: float, a2: float, a1: float, a0: float, t_s: np.ndarray, delay_s: float) -> np.ndarray:
    """Unit-step response of n0 / (s^3 + a2 s^2 + a1 s + a0), delayed by `delay_s`, on the
    equally spaced `t_s` (the delay a whole number of its steps)."""
    out = np.zeros(len(t_s))
    late = t_s >= delay_s - 1e-12
    if late.sum() >= 2:
        out[late] = lti_response([n0], [1.0, a2, a1, a0], np.ones(int(late.sum())), float(t_s[1] - t_s[0]))
    return out


def fit_index(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Eq. 5.12."""
    spread = np.linalg.norm(measured - measured.mean())
    return float(1.0 - np.linalg.norm(measured - simulated) / spread) if spread > 0 else float("nan")


def fit_closed_loop(t_s: np.ndarray, dy_m: np.ndarray, step_m: float, delay_s: float, k_v_m: float,
                    guess: tuple) -> dict:
    """Gcl(s) = n0 / (s^3 + a2 s^2 + a1 s + a0) from one reference step (output error), in the
    structure eq. 5.4 gives a type-I plant under u = K e: a0 = n0 = K k01 b0, a1 = b0, a2 = b1.
    (A free a0 drifted to wherever the window's friction put it: the "pole near the origin"
    of chapter 5.4.1, there removed by hand; here it never enters.) `guess`: (b0, b1, k01)."""
    from scipy.optimize import least_squares
    def model(q):
        b0, b1, k01 = np.exp(q)
        n0 = k_v_m * k01 * b0
        return step_m * closed_loop_step(n0, b1, b0, n0, t_s, delay_s)

    result = least_squares(lambda q: model(q) - dy_m, np.log(guess), method="lm", max_nfev=400)
    b0, b1, k01 = np.exp(result.x)
    n0 = k_v_m * k01 * b0
    return {"n0": n0, "a2": b1, "a1": b0, "a0": n0, "fit": fit_index(dy_m, model(result.x))}


def open_loop_from_closed(gcl: dict, k_v_m: float) -> dict | None:
    """Eq. 5.5 and the pole correction: b0 [1/s^2], b1 [1/s], k01 [(m/s)/V]."""
    n0, a2, a1, a0 = gcl["n0"], gcl["a2"], gcl["a1"], gcl["a0"]
    poles = np.roots([1.0, a2, a1, a0 - n0])                       # eq. 5.5: denGcl - numGcl
    complex_ = poles[np.abs(poles.imag) > 1e-9]
    real = poles[np.abs(poles.imag) <= 1e-9]
    if len(complex_) != 2 or len(real) != 1:
        return None                                                # no underdamped pair: no 5.2 model
    p = complex_[0]
    b0, b1 = float(abs(p) ** 2), float(-2.0 * p.real)
    return {"b0": b0, "b1": b1, "k01": float(n0 / (k_v_m * b0)), "pole": (float(p.real), float(abs(p.imag))),
            "removed_pole": float(real[0].real)}


def closed_loop_of(plant: dict, k_v_m: float) -> tuple[float, float, float, float]:
    """Gcl of G = k01 b0 / (s (s^2 + b1 s + b0)) under u = K e (eq. 5.3-5.4)."""
    n0 = k_v_m * plant["k01"] * plant["b0"]
    return n0, plant["b1"], plant["b0"], n0


def low_pass(x: np.ndarray, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """4th-order Butterworth, zero phase (chapter 5.4.1's filter, run forward and back)."""
    from scipy import signal
    sos = signal.butter(4, cutoff_hz, fs=rate_hz, output="sos")
    return signal.sosfiltfilt(sos, x)


def force_terms(y_m: np.ndarray, pl_pa: np.ndarray, area_m2: float, period_s: float,
                cutoff_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Eq. 5.6's measured terms through the zero-phase low-pass: (A PL [N], y' [m/s], y''
    [m/s^2]); None for a record too short or with gaps."""
    if len(y_m) < 20 or not (np.all(np.isfinite(y_m)) and np.all(np.isfinite(pl_pa))):
        return None
    rate = 1.0 / period_s
    velocity = np.gradient(low_pass(y_m, cutoff_hz, rate), period_s)
    return area_m2 * low_pass(pl_pa, cutoff_hz, rate), velocity, np.gradient(velocity, period_s)


def motion_parameters(terms: tuple | None) -> dict | None:
    """m [kg], sigma [N s/m], Fe [N] from A PL = m y'' + sigma y' + Fe (eq. 5.6-5.7) on
    `force_terms`."""
    if terms is None:
        return None
    force, velocity, accel = terms
    a = np.column_stack([accel, velocity, np.ones_like(force)])
    (m, sigma, fe), *_ = np.linalg.lstsq(a, force, rcond=None)             # eq. 5.7
    return {"m": float(m), "sigma": float(sigma), "fe": float(fe)}


def load_change(terms: tuple, mass_kg: float, sigma_ns_m: float, rest: int) -> np.ndarray:
    """delta Fe [N] of eq. 5.6 over a window: Fe = A PL - m y'' - sigma y' on `force_terms`,
    less its mean over the first `rest` samples (at rest before the change); the samples after."""
    force, velocity, accel = terms
    fe = force - mass_kg * accel - sigma_ns_m * velocity
    return fe[rest:] - float(np.mean(fe[:rest]))


def complete_response(plant: dict, k_v_m: float, mass_kg: float, sigma_ns_m: float, area_m2: float,
                      t_s: np.ndarray, step_m: float, load_n: np.ndarray, delay_s: float) -> np.ndarray:
    """Eq. 5.11 under u = K e: the output change [m] a reference step of `step_m` and the load's
    change `load_n` [N] (on `t_s`) drive, G(s) = `plant` (b0, b1, k01 in SI) and the load's path
    from the sensibilities of `plant`, m, sigma (eq. 5.8-5.10): -k02 b0 (s + z0) /
    (s^3 + b1 s^2 + b0 s + K k01 b0)."""
    path = complete_model(*sensibilities(plant["b0"], plant["b1"], plant["k01"], mass_kg, sigma_ns_m, area_m2),
                          mass_kg, sigma_ns_m, area_m2)
    n0, a2, a1, a0 = closed_loop_of(plant, k_v_m)
    gain = -path["k02"] * plant["b0"]
    load = lti_response([gain, gain * path["z0"]], [1.0, a2, a1, a0], load_n, float(t_s[1] - t_s[0]))
    return step_m * closed_loop_step(n0, a2, a1, a0, t_s, delay_s) + load


def complete_fits(plant: dict, mass_kg: float, sigma_ns_m: float, area_m2: float, windows: list[dict],
                  delay_s: float) -> np.ndarray:
    """Eq. 5.12 of the complete model on each window (keys t, dy, step_m, k_v_m, load_n)."""
    return np.array([fit_index(w["dy"], complete_response(plant, w["k_v_m"], mass_kg, sigma_ns_m, area_m2, w["t"],
                                                          w["step_m"], w["load_n"], delay_s)) for w in windows])


def refine_complete(plant: dict, mass_kg: float, sigma_ns_m: float, area_m2: float, windows: list[dict],
                    delay_s: float, iterations: int = 300) -> dict:
    """Chapter 5.2.4's refinement: Kx, Kd, Kp changed to maximise eq. 5.12 of the complete model
    over `windows` (their mean), from the ones `plant` gives. With m and sigma held, eq.
    5.8-5.10 map Kx, Kd, Kp one to one onto b0, b1, k01: those are searched (Nelder-Mead on
    their logarithms); the refined G(s) is returned."""
    from scipy.optimize import minimize

    def plant_of(q):
        b0, b1, k01 = np.exp(q)
        return {"b0": float(b0), "b1": float(b1), "k01": float(k01)}

    def cost(q):
        return -float(np.mean(complete_fits(plant_of(q), mass_kg, sigma_ns_m, area_m2, windows, delay_s)))
    start = np.log([plant["b0"], plant["b1"], plant["k01"]])
    result = minimize(cost, start, method="Nelder-Mead", options={"maxiter": iterations, "xatol": 1e-3,
                                                                  "fatol": 1e-5})
    return plant_of(result.x)


def sensibilities(b0: float, b1: float, k01: float, mass_kg: float, sigma_ns_m: float,
                  area_m2: float) -> tuple[float, float, float]:
    """Eq. 5.8-5.10: (Kx [Pa/s per V], Kd [Pa/m], Kp [1/s]) from G(s) (b0 [1/s^2], b1 [1/s],
    k01 [(m/s)/V]) and the motion parameters m [kg], sigma [N s/m] on a piston of `area_m2`."""
    kp = sigma_ns_m / mass_kg - b1                               # eq. 5.8
    kd = (mass_kg * b0 + sigma_ns_m * kp) / area_m2              # eq. 5.9
    kx = mass_kg * b0 * k01 / area_m2                            # eq. 5.10
    return kx, kd, kp


def complete_model(kx: float, kd: float, kp: float, mass_kg: float, sigma_ns_m: float, area_m2: float) -> dict:
    """Eq. 5.11 from the sensibilities: Y = k01 b0 / (s (s^2 + b1 s + b0)) Xv - k02 b0 (s + z0) /
    (s (s^2 + b1 s + b0)) Fe, Fe a force against the piston (A PL = m y'' + sigma y' + Fe with
    eq. 4.50): b1 = sigma/m - Kp, b0 = (A Kd - sigma Kp)/m, k01 = A Kx / (m b0), k02 = 1 / (m b0)
    [m/N], z0 = -Kp [1/s]."""
    b1 = sigma_ns_m / mass_kg - kp
    b0 = (area_m2 * kd - sigma_ns_m * kp) / mass_kg
    return {"b0": b0, "b1": b1, "k01": area_m2 * kx / (mass_kg * b0), "k02": 1.0 / (mass_kg * b0), "z0": -kp}


def quadratic_fit(positions_m: np.ndarray, values: np.ndarray) -> np.ndarray | None:
    """Chapter 5.2.3's second-order polynomial in the position (coefficients, highest first);
    None below three positions."""
    ok = np.isfinite(values)
    return np.polyfit(positions_m[ok], values[ok], 2) if ok.sum() >= 3 else None


def load_pressure_signals(u_v: np.ndarray, y_m: np.ndarray, pl_pa: np.ndarray, period_s: float,
                          cutoff_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One window's (xv, y', PL, PL') through the zero-phase low-pass (the valve input already
    aligned with the cycle it acts in)."""
    rate = 1.0 / period_s
    xv, y, pl = (low_pass(x, cutoff_hz, rate) for x in (u_v, y_m, pl_pa))
    return xv, np.gradient(y, period_s), pl, np.gradient(pl, period_s)


def load_pressure_fit(windows: list[tuple]) -> tuple[float, float, float]:
    """(Kx [Pa/s per V], Kd [Pa/m], Kp [1/s]) of PL' = Kx xv - Kd y' + Kp PL + c_w (eq. 4.50, each
    window w its own operating point c_w) by least squares over `windows` of
    `load_pressure_signals`."""
    rows = sum(len(w[0]) for w in windows)
    a, b, start = np.zeros((rows, 3 + len(windows))), np.zeros(rows), 0
    for j, (xv, velocity, pl, rate) in enumerate(windows):
        part = slice(start, start + len(xv))
        a[part, 0], a[part, 1], a[part, 2], a[part, 3 + j] = xv, -velocity, pl, 1.0
        b[part] = rate
        start += len(xv)
    (kx, kd, kp, *_), *_ = np.linalg.lstsq(a, b, rcond=None)
    return float(kx), float(kd), float(kp)


def scheduled_parameter(set_points_m: np.ndarray, values: np.ndarray, at_m: float) -> float:
    """One parameter of the scheduled model at `at_m`: the spline through (set point, value)
    of one load (cubic from four points, else the highest order the points allow: the
    thesis's 2-D table's spline interpolation)."""
    from scipy.interpolate import make_interp_spline
    order = min(3, len(set_points_m) - 1)
    if order < 1:
        return float(values[0])
    return float(make_interp_spline(set_points_m, values, k=order)(at_m))


def leave_one_out(set_points_m: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Each interior point's value as the scheduled model reads it from the others (NaN at the
    ends: the table would extrapolate there)."""
    out = np.full(len(values), np.nan)
    for i in range(1, len(values) - 1):
        keep = np.arange(len(values)) != i
        out[i] = scheduled_parameter(set_points_m[keep], values[keep], set_points_m[i])
    return out
