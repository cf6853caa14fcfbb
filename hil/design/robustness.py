"""Robustness analysis of the position loop (chapters 7.3-7.4): well-posedness of P, PI, PD
and PID, internal stability of a PI on the nominal plant, the multiplicative uncertainty of
a plant set and its weight W1, the small-gain test and the robust-performance figure.

Transfer functions are numpy coefficient arrays (highest power first) and frequency
responses come from `scipy.signal.freqs`; H-infinity norms are the peak of |H(jw)| on a
dense logarithmic grid refined by a bounded scalar search around it (SISO, stable H: the
norm is that peak). SI throughout: plants in m/V, gains in V/m, W1 dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal

from hil.design.plants import Plant

W_RANGE_RAD_S = (1e-2, 1e3)          # chapter 7.4.1.1: the uncertainty's frequency range
GRID_POINTS = 4000
WEIGHT_MARGIN = 1.05                 # the fitted W1 lies this far above the largest error, at least
FIT_POINTS = 200                     # of the grid, for the weight's fit (checked on all of it)


def polymul(*polys: np.ndarray) -> np.ndarray:
    out = np.array([1.0])
    for p in polys:
        out = np.polymul(out, p)
    return out


def degree(p: np.ndarray) -> int:
    nz = np.flatnonzero(np.abs(np.asarray(p, float)) > 1e-12 * max(np.max(np.abs(p)), 1e-300))
    return len(p) - 1 - int(nz[0]) if len(nz) else -1


def grid(points: int = GRID_POINTS) -> np.ndarray:
    return np.logspace(np.log10(W_RANGE_RAD_S[0]), np.log10(W_RANGE_RAD_S[1]), points)


def response(num: np.ndarray, den: np.ndarray, w: np.ndarray) -> np.ndarray:
    return signal.freqs(num, den, worN=w)[1]


# -- controllers and well-posedness (Table 7.1 / B.1, eq. 7.6) ------------------------------------
def controller(kind: str, kp: float = 1.0, ki: float = 1.0, kd: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """K(s) = num/den of P, PI, PD, PID (ideal derivative, as Table 7.1 writes them)."""
    return {"P": (np.array([kp]), np.array([1.0])),
            "PI": (np.array([kp, ki]), np.array([1.0, 0.0])),
            "PD": (np.array([kd, kp]), np.array([1.0])),
            "PID": (np.array([kd, kp, ki]), np.array([1.0, 0.0]))}[kind]


@dataclass
class ClosedLoopMap:
    name: str
    num_degree: int
    den_degree: int

    @property
    def proper(self) -> bool:
        return self.num_degree <= self.den_degree


def well_posedness(plant: Plant, g2_num: np.ndarray) -> dict[str, list[ClosedLoopMap]]:
    """Eq. 7.6's maps K/(1+KG1), KG1/(1+KG1), KG2/(1+KG1) for each controller, G2 = g2_num /
    (s (s^2 + b1 s + b0)); well-posed when every map is proper (Definition 5.1 of the thesis's [157])."""
    n1, d1 = plant.num(), plant.den()
    table = {}
    for kind in ("P", "PI", "PD", "PID"):
        nk, dk = controller(kind)
        closed = np.polyadd(polymul(dk, d1), polymul(nk, n1))          # the common denominator
        table[kind] = [ClosedLoopMap("K/(1+KG1)", degree(polymul(nk, d1)), degree(closed)),
                       ClosedLoopMap("KG1/(1+KG1)", degree(polymul(nk, n1)), degree(closed)),
                       ClosedLoopMap("KG2/(1+KG1)", degree(polymul(nk, g2_num)), degree(closed))]
    return table


# -- the PI on one plant: poles and internal stability (eq. 7.16-7.21) ------------------------------
def pi_characteristic(plant: Plant, kp: float, ki: float) -> np.ndarray:
    """s^4 + b1 s^3 + b0 s^2 + Kp k1 b0 s + Ki k1 b0: the denominator of eq. 7.17-7.20."""
    kb = plant.k01 * plant.b0
    return np.array([1.0, plant.b1, plant.b0, kp * kb, ki * kb])


def internal_stability_maps(plant: Plant, kp: float, ki: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The four maps of eq. 7.16 (as eq. 7.17-7.20 write them), from (w1, w2) to (e1, e2)."""
    den = pi_characteristic(plant, kp, ki)
    kb = plant.k01 * plant.b0
    sensitivity = polymul(np.array([1.0, 0.0, 0.0]), np.array([1.0, plant.b1, plant.b0]))
    return {"(I - KP)^-1 (7.17)": (sensitivity, den),
            "P (I - KP)^-1 (7.18)": (np.array([kb, 0.0]), den),
            "K (I - PK)^-1 (7.19)": (polymul(np.array([kp, ki]), np.array([1.0, plant.b1, plant.b0, 0.0])), den),
            "(I - PK)^-1 (7.20)": (sensitivity, den)}


def closed_loop_poles(plant: Plant, kp: float, ki: float) -> np.ndarray:
    """Eq. 7.21: the roots of the common denominator, sorted by real part then imaginary."""
    poles = np.roots(pi_characteristic(plant, kp, ki))
    return poles[np.lexsort((-poles.imag, -poles.real))]


def internally_stable(plant: Plant, kp: float, ki: float) -> bool:
    """Every map of eq. 7.16 in RH-infinity: proper and all poles in the open left half plane."""
    maps = internal_stability_maps(plant, kp, ki)
    return all(degree(n) <= degree(d) and np.all(np.roots(d).real < 0) for n, d in maps.values())


# -- multiplicative uncertainty and its weight (eq. 7.9, 7.14, 7.15) -------------------------------
def multiplicative_error(plants: list[Plant], nominal: Plant, w: np.ndarray) -> np.ndarray:
    """|(P_i - P0) / P0| on `w` (eq. 7.14 with W2 = 1), one row per plant."""
    p0 = nominal.response(w)
    return np.array([np.abs(p.response(w) / p0 - 1.0) for p in plants])


def _weight(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """g (s + a)(s^2 + b s + c) / ((s + d)(s^2 + e s + f)) from logs: every coefficient of each
    factor positive, so W1 is stable and minimum phase whatever the fit does."""
    g, a, b, c, d, e, f = np.exp(q)
    return g * polymul([1.0, a], [1.0, b, c]), polymul([1.0, d], [1.0, e, f])


def fit_weight(w: np.ndarray, bound: np.ndarray, margin: float = WEIGHT_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """A stable, minimum-phase third-order W1(s) with |W1(jw)| >= margin x `bound` on `w`
    (chapter 7.4.1.1: the thesis fitted one to points picked above Fig. 7.4's maximum error).
    Least squares on the log magnitude, penalising the points under the bound ten times as
    much, then the gain raised until none is under it."""
    pick = np.unique(np.linspace(0, len(w) - 1, FIT_POINTS).astype(int))     # the fit's points
    wf, target = w[pick], np.log(margin * np.maximum(bound[pick], 1e-9))

    def residual(q):
        gap = np.log(np.abs(response(*_weight(q), wf))) - target
        return np.where(gap < 0.0, 10.0 * gap, gap)

    w_mid = float(np.sqrt(w[0] * w[-1]))
    starts = [np.log([bound[-1], 10.0, 2 * w_mid, w_mid ** 2, 10.0, 2 * w_mid, w_mid ** 2]),
              np.log([bound[-1], 1.0, 100.0, 1e4, 1.0, 300.0, 3e4]),
              np.log([bound[-1], 0.1, 200.0, 2e6, 50.0, 300.0, 3e4])]
    # coefficients kept within 1e-6..1e9 (the flat bound of a pure gain error otherwise lets
    # pole and zero run off together to overflow)
    lo, hi = np.full(7, np.log(1e-6)), np.full(7, np.log(1e9))
    best = min((optimize.least_squares(residual, np.clip(q0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi),
                                       method="trf", max_nfev=4000) for q0 in starts),
               key=lambda r: r.cost)
    num, den = _weight(best.x)
    shortfall = float(np.max(margin * bound / np.abs(response(num, den, w))))
    return num * max(shortfall, 1.0), den


# -- norms ------------------------------------------------------------------------------------------
def cancel_origin(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cancel the powers of s common to both (the integrators of P0 and K against the zeros
    at the origin of S): an exact cancellation, done on the coefficients."""
    num, den = np.trim_zeros(np.asarray(num, float), "f"), np.trim_zeros(np.asarray(den, float), "f")
    while len(num) > 1 and len(den) > 1 and num[-1] == 0.0 and den[-1] == 0.0:
        num, den = num[:-1], den[:-1]
    return num, den


def hinf(num: np.ndarray, den: np.ndarray, w: np.ndarray | None = None) -> tuple[float, float]:
    """(||H||inf, the frequency of the peak) of a stable proper SISO H = num/den: the peak of
    |H(jw)| on `w` (default: 1e-3 to 1e5 rad/s), refined by a bounded search around it; inf
    when H is unstable or improper."""
    num, den = cancel_origin(num, den)
    if degree(num) > degree(den) or np.any(np.roots(den).real >= 0):
        return float("inf"), float("nan")
    w = np.logspace(-3, 5, 8000) if w is None else w
    mag = np.abs(response(num, den, w))
    k = int(np.argmax(mag))
    lo, hi = np.log10(w[max(k - 1, 0)]), np.log10(w[min(k + 1, len(w) - 1)])
    if hi > lo:
        r = optimize.minimize_scalar(lambda x: -abs(response(num, den, np.array([10.0 ** x]))[0]),
                                     bounds=(lo, hi), method="bounded", options={"xatol": 1e-9})
        if -r.fun > mag[k]:
            return float(-r.fun), float(10.0 ** r.x)
    return float(mag[k]), float(w[k])


def open_loop(plant: Plant, kp: float, ki: float) -> tuple[np.ndarray, np.ndarray]:
    """L = K P0 of the PI."""
    return polymul(np.array([kp, ki]), plant.num()), polymul(np.array([1.0, 0.0]), plant.den())


def complementary(plant: Plant, kp: float, ki: float) -> tuple[np.ndarray, np.ndarray]:
    """T = L / (1 + L)."""
    nl, dl = open_loop(plant, kp, ki)
    return nl, np.polyadd(dl, nl)


def sensitivity(plant: Plant, kp: float, ki: float) -> tuple[np.ndarray, np.ndarray]:
    """S = 1 / (1 + L)."""
    nl, dl = open_loop(plant, kp, ki)
    return dl, np.polyadd(dl, nl)


def step_on_plant(plant: Plant, kp: float, ki: float, step_m: float = 0.010, t_end_s: float = 3.0) -> dict:
    """The linear loop's step response (T = L / (1 + L)) on one plant: overshoot (%) and
    settling (5 %) as the HIL analysis measures them (`hil.metrics.step_response`)."""
    from hil.metrics import step_response
    t = np.linspace(0.0, t_end_s, 3001)
    _, y = signal.step(complementary(plant, kp, ki), T=t)
    return step_response(t, y * step_m, 0.0, step_m)


def steps_on_plants(plants: list[Plant], kp: float, ki: float) -> dict:
    """The worst overshoot and settling of the linear PI loop over a plant set."""
    rows = [(p, step_on_plant(p, kp, ki)) for p in plants]
    worst_os = max(rows, key=lambda r: r[1]["overshoot_pct"])
    worst_ts = max(rows, key=lambda r: r[1]["settling_s"])
    return {"overshoot_pct_max": worst_os[1]["overshoot_pct"], "overshoot_worst_plant": worst_os[0].label,
            "overshoot_pct_min": min(r[1]["overshoot_pct"] for r in rows),
            "settling_s_max": worst_ts[1]["settling_s"], "settling_worst_plant": worst_ts[0].label}


def small_gain(plant: Plant, kp: float, ki: float, w1: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
    """||W1 T||inf (eq. 7.22, Theorem 2): <= 1 means robustly stable for every plant in the set."""
    nt, dt = complementary(plant, kp, ki)
    return hinf(polymul(w1[0], nt), polymul(w1[1], dt))


def disturbance_response(plant: Plant, kp: float, ki: float, w0: tuple[np.ndarray, np.ndarray]
                         ) -> tuple[float, float]:
    """||S W0||inf: the nominal loop's output per unit external force (W0 = G2 of P0)."""
    ns, ds = sensitivity(plant, kp, ki)
    return hinf(polymul(ns, w0[0]), polymul(ds, w0[1]))


def robust_performance_bound(plant: Plant, kp: float, ki: float, w1: tuple, w0: tuple, wdm: tuple,
                             w: np.ndarray | None = None) -> float:
    """The worst |T_yd| over every plant of (1 + W1 D) P0 and every G2 of (1 + Wdm Dd) W0
    (eq. 7.25), bounded pointwise: |W0| (1 + |Wdm|) / (|1 + L0| - |W1 L0|), valid where the
    small-gain test holds (the denominator stays positive); inf where it does not."""
    w = np.logspace(-3, 5, 8000) if w is None else w
    l0 = response(*open_loop(plant, kp, ki), w)
    margin = np.abs(1.0 + l0) - np.abs(response(*w1, w) * l0)
    if np.any(margin <= 0):
        return float("inf")
    return float(np.max(np.abs(response(*w0, w)) * (1.0 + np.abs(response(*wdm, w))) / margin))
