"""Servo-hydraulic actuator physics (thesis chapter 4.3), pure and in place: the emulator's
plant and the controller's model of it (its residuals) use these laws, each with its own
parameters.

One actuator = a four-way servo-valve feeding an asymmetric double-acting cylinder. The
state of leg i lives in a row of a float64 array (`S_*` columns); physical parameters are
packed once into a float64 vector (`HP_*` entries) by `pack`. Kernels are
numba-compiled and allocate nothing, so the rigs can call them every sub-step.

Modelling choices (all SI, gauge pressures):
- Valve orifices: eq. 4.2 Q = c x sqrt|dP| sign(dP) per metering edge, the edges combined as
  eq. 4.4-4.6. The spool position x is the fraction of full valve input. The edges carry
  a small underlap (`lap_p` on the supply edges, `lap_t` on the return edges): at null all
  four edges pass a little flow, which is what gives the identified actuator its damping
  (chapter 5: zeta ~ 0.5, far more than a critically lapped valve and friction give).
  With both laps 0 the edges are exactly eq. 4.4-4.6. sqrt|dP| is regularised to a laminar
  law below `laminar_pa` so the flow is smooth (and its slope finite) at dP = 0.
- Spool: first-order lag. The thesis neglects spool dynamics (4.3); the Moog E050's
  bandwidth (> 100 Hz) is well above the actuator's ~17 Hz hydraulic mode, and a second
  order valve resonance would sit beyond the 250 Hz Nyquist limit of the 500 Hz loop, so a
  first-order lag is all the loop can see. It is integrated exactly.
- Chambers: continuity eq. 4.7-4.8 with internal (A <-> B) leakage, volumes eq. 4.9-4.10
  with dead volumes that include the hoses, and an effective bulk modulus that depends on
  the absolute chamber pressure: oil, entrained air (polytropic) and the hose wall in
  series. Integrated linearly-implicitly per chamber (stable for stiff orifices and small
  volumes at any sub-step).
- Where the A <-> B leakage flows: the calibrated leakage (`HP_LEAK`, the damping the
  identification sees) is a lumped path on the valve side of the load-holding valves, the
  servo-valve's spool clearances at null; the piston seal itself leaks only `HP_SEAL_LEAK`.
  So closing the ports (`ports` = 0) cuts the lumped path and the cylinder holds its load:
  with the lumped leakage across the piston a blocked leg under 20 bar of load pressure
  would run at ~0.2 m/s, which no real load-holding valve allows.
- Force on the piston eq. 4.15 / 4.24: F = Ap (PA - alpha PB).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from physics import actuator
from physics.constants import ATMOSPHERE_PA, BAR, CM3, L_MIN
from program.sections import Key, Section, frozen, key

# -- parameter vector (filled by `pack`) ---------------------------------------------------
HP_AREA_A = 0          # piston area Ap [m^2]
HP_ALPHA = 1           # annulus / piston area ratio
HP_STROKE = 2          # [m]
HP_VA0 = 3             # dead volume of chamber A incl. hose [m^3]
HP_VB0 = 4
HP_BETA_OIL = 5        # [Pa]
HP_AIR0 = 6            # entrained air volume fraction at atmospheric pressure
HP_POLY_N = 7          # polytropic index of the air
HP_BETA_WALL = 8       # hose/wall compliance as a bulk modulus [Pa]
HP_KV = 9              # orifice coefficient per edge at full opening [m^3/s/sqrt(Pa)]
HP_LAP_P = 10          # supply-edge underlap [fraction of full spool stroke]
HP_LAP_T = 11          # return-edge underlap
HP_LEAK = 12           # cross-piston leakage [m^3/s/Pa]
HP_TANK = 13           # return-line pressure [Pa]
HP_LAMINAR = 14        # laminar transition pressure of the orifice law [Pa]
HP_TAU_SPOOL = 15      # spool time constant [s]
HP_P_MIN = 16          # lowest chamber pressure (cavitation) [Pa gauge]
HP_SEAL_LEAK = 17      # leakage across the piston seal itself [m^3/s/Pa]
HP_SIZE = 18

# -- per-leg state columns -------------------------------------------------------------------
S_Y = 0        # piston position from fully retracted [m]
S_V = 1        # piston velocity [m/s] (testbench; the hexapod reads it from MuJoCo)
S_PA = 2       # chamber pressures [Pa gauge]
S_PB = 3
S_SPOOL = 4    # spool position [fraction of full input]
S_Z = 5        # LuGre bristle deflection of the cylinder seals [m]
S_ZG = 6       # LuGre bristle deflection of the linear guide [m] (testbench)
S_SIZE = 7


@numba.njit(cache=True, inline="always")
def orifice_root(dp: float, laminar_pa: float) -> float:
    """sqrt|dp| sign(dp) of eq. 4.2, laminar (linear) below `laminar_pa`."""
    return orifice_root_and_slope(dp, laminar_pa)[0]


@numba.njit(cache=True, inline="always")
def orifice_root_and_slope(dp: float, laminar_pa: float):
    """eq. 4.2's sqrt|dp| sign(dp), regularised as dp / q^(1/4) with q = dp^2 + laminar^2
    (laminar below `laminar_pa`), and its slope d/d dp (positive, finite at dp = 0), from one
    fourth root (two square roots, several times faster than pow)."""
    q = dp * dp + laminar_pa * laminar_pa
    root4 = math.sqrt(math.sqrt(q))
    return dp / root4, (0.5 * dp * dp + laminar_pa * laminar_pa) / (q * root4)


@numba.njit(cache=True, inline="always")
def edge_pair_flow(a_in: float, dp_in: float, a_out: float, dp_out: float, laminar_pa: float):
    """One chamber's flow in through its supply edge (opening `a_in`, drop `dp_in`) less
    the flow out through its return edge (eq. 4.2 each), and the sum of the edges' root
    slopes; a closed edge (opening 0) passes nothing and is not evaluated."""
    flow, slope = 0.0, 0.0
    if a_in > 0.0:
        root, root_slope = orifice_root_and_slope(dp_in, laminar_pa)
        flow, slope = a_in * root, a_in * root_slope
    if a_out > 0.0:
        root, root_slope = orifice_root_and_slope(dp_out, laminar_pa)
        flow, slope = flow - a_out * root, slope + a_out * root_slope
    return flow, slope


@numba.njit(cache=True)
def valve_flows(spool: float, pa: float, pb: float, ps: float, hp: np.ndarray):
    """Flows into chambers A and B through the valve (eq. 4.4-4.6 with edge underlap),
    and their slopes d QA / d PA, d QB / d PB (for the implicit pressure update)."""
    kv, lam, pt = hp[HP_KV], hp[HP_LAMINAR], hp[HP_TANK]
    a_pa = max(spool + hp[HP_LAP_P], 0.0)     # P -> A opens with positive spool
    a_at = max(hp[HP_LAP_T] - spool, 0.0)     # A -> T opens with negative spool
    a_pb = max(hp[HP_LAP_P] - spool, 0.0)     # P -> B
    a_bt = max(spool + hp[HP_LAP_T], 0.0)     # B -> T
    qa, dqa = edge_pair_flow(a_pa, ps - pa, a_at, pa - pt, lam)
    qb, dqb = edge_pair_flow(a_pb, ps - pb, a_bt, pb - pt, lam)
    return kv * qa, kv * qb, -kv * dqa, -kv * dqb


@numba.njit(cache=True)
def supply_flow(spool: float, pa: float, pb: float, ps: float, hp: np.ndarray, ports: float):
    """The flow the valve draws from the supply through its P edges (eq. 4.4-4.6; negative
    when a chamber above the supply drives oil back) and its slope d / d ps; nothing through
    closed load-holding valves (`ports` 0, as `pressure_rates`)."""
    kv, lam = hp[HP_KV] * ports, hp[HP_LAMINAR]
    into_a, slope_a = edge_pair_flow(max(spool + hp[HP_LAP_P], 0.0), ps - pa, 0.0, 0.0, lam)
    into_b, slope_b = edge_pair_flow(max(hp[HP_LAP_P] - spool, 0.0), ps - pb, 0.0, 0.0, lam)
    return kv * (into_a + into_b), kv * (slope_a + slope_b)


@numba.njit(cache=True)
def valve_flow_gains(spool: float, pa: float, pb: float, ps: float, hp: np.ndarray):
    """d QA / d spool and d QB / d spool of `valve_flows` at fixed pressures: each open
    metering edge's kv sqrt|dP| (eq. 4.2)."""
    kv, lam, pt = hp[HP_KV], hp[HP_LAMINAR], hp[HP_TANK]
    ga = (kv * orifice_root(ps - pa, lam) if spool + hp[HP_LAP_P] > 0.0 else 0.0) + (
        kv * orifice_root(pa - pt, lam) if hp[HP_LAP_T] - spool > 0.0 else 0.0)
    gb = (kv * orifice_root(ps - pb, lam) if hp[HP_LAP_P] - spool > 0.0 else 0.0) + (
        kv * orifice_root(pb - pt, lam) if spool + hp[HP_LAP_T] > 0.0 else 0.0)
    return ga, -gb


@numba.njit(cache=True)
def bulk_modulus(p: float, hp: np.ndarray) -> float:
    """Effective bulk modulus at gauge pressure p: oil with entrained air, hose wall in series.

    Air of volume fraction eps0 at atmospheric pressure is compressed polytropically,
    eps(p) = eps0 (p_atm / p_abs)^(1/n); its compliance eps / (n p_abs) adds to the oil's,
    per unit of mixture volume; the hose wall adds 1 / beta_wall.
    """
    p_abs = max(p + ATMOSPHERE_PA, 1000.0)
    n = hp[HP_POLY_N]
    ratio = ATMOSPHERE_PA / p_abs
    # isothermal air (n = 1, the configured hoses) needs no power: the same value, exactly
    eps = hp[HP_AIR0] * (ratio if n == 1.0 else ratio ** (1.0 / n))
    compliance = (1.0 / hp[HP_BETA_OIL] + eps / (n * p_abs)) / (1.0 + eps) + 1.0 / hp[HP_BETA_WALL]
    return 1.0 / compliance


@numba.njit(cache=True, inline="always")
def chamber_volumes(y: float, hp: np.ndarray):
    """eq. 4.9-4.10 with y from the retracted end: VA = VA0 + Ap y, VB = VB0 + alpha Ap (S - y)."""
    area = hp[HP_AREA_A]
    yc = min(max(y, 0.0), hp[HP_STROKE])
    return hp[HP_VA0] + area * yc, hp[HP_VB0] + hp[HP_ALPHA] * area * (hp[HP_STROKE] - yc)


@numba.njit(cache=True)
def column_stiffness(y: float, pa: float, pb: float, hp: np.ndarray) -> float:
    """The oil columns' stiffness felt at the piston with the ports blocked [N/m]:
    d(Ap (PA - alpha PB)) / d(-y) of eq. 4.7-4.8, Ap^2 (beta_A / VA + alpha^2 beta_B / VB)."""
    va, vb = chamber_volumes(y, hp)
    area, alpha = hp[HP_AREA_A], hp[HP_ALPHA]
    return area * area * (bulk_modulus(pa, hp) / va + alpha * alpha * bulk_modulus(pb, hp) / vb)


@numba.njit(cache=True)
def force_rate_per_spool(y: float, pa: float, pb: float, spool: float, ps: float, hp: np.ndarray) -> float:
    """d(dF/dt) / d spool of the piston force F = Ap (PA - alpha PB) at fixed pressures and
    piston velocity (eq. 4.2, 4.7-4.8): Ap (beta_A / VA dQA/dx - alpha beta_B / VB dQB/dx),
    N/s per unit spool: a force loop of gain k (spool per N) on it has the bandwidth k times it."""
    ga, gb = valve_flow_gains(spool, pa, pb, ps, hp)
    va, vb = chamber_volumes(y, hp)
    return hp[HP_AREA_A] * (bulk_modulus(pa, hp) / va * ga - hp[HP_ALPHA] * bulk_modulus(pb, hp) / vb * gb)


@numba.njit(cache=True, inline="always")
def piston_force(pa: float, pb: float, hp: np.ndarray) -> float:
    """eq. 4.15 / 4.24: hydraulic force on the piston, positive extending."""
    return actuator.piston_force(pa, pb, hp[HP_AREA_A], hp[HP_ALPHA])


@numba.njit(cache=True)
def pressure_rates(y: float, v: float, pa: float, pb: float, spool: float, ps: float, hp: np.ndarray,
                   ports: float, seal_leak: float):
    """dPA/dt, dPB/dt (eq. 4.7-4.8, 4.13-4.14 with internal leakage) and their slopes;
    `ports` 1 = the valve connected to the chambers, 0 = the load-holding valves closed;
    `seal_leak` the piston seal's leakage [m^3/s/Pa] (`HP_SEAL_LEAK` when it is sound)."""
    qa, qb, dqa, dqb = valve_flows(spool, pa, pb, ps, hp)
    qa, qb, dqa, dqb = qa * ports, qb * ports, dqa * ports, dqb * ports
    leak_coefficient = hp[HP_LEAK] * ports + seal_leak
    leak = leak_coefficient * (pa - pb)
    va, vb = chamber_volumes(y, hp)
    ka = bulk_modulus(pa, hp) / va
    kb = bulk_modulus(pb, hp) / vb
    area = hp[HP_AREA_A]
    rate_a = ka * (qa - leak - area * v)
    rate_b = kb * (qb + leak + hp[HP_ALPHA] * area * v)
    return rate_a, rate_b, ka * (dqa - leak_coefficient), kb * (dqb - leak_coefficient)


@numba.njit(cache=True)
def spool_step(spool: float, command: float, h: float, hp: np.ndarray) -> float:
    """Exact first-order lag toward the command (saturated at full input)."""
    return spool_lag(spool, command, spool_decay(h, hp))


@numba.njit(cache=True, inline="always")
def spool_decay(h: float, hp: np.ndarray) -> float:
    """The spool lag's factor over a step h: exp(-h / tau)."""
    return math.exp(-h / hp[HP_TAU_SPOOL])


@numba.njit(cache=True, inline="always")
def spool_lag(spool: float, command: float, decay: float) -> float:
    """`spool_step` with its step's `spool_decay` computed once for many steps."""
    target = min(max(command, -1.0), 1.0)
    return target + (spool - target) * decay


@numba.njit(cache=True)
def chamber_step(state: np.ndarray, y: float, v: float, ps: float, h: float, hp: np.ndarray,
                 ports: float, seal_leak: float) -> None:
    """Advance PA, PB of one leg's state row by h, linearly implicit (Rosenbrock-Euler
    on each chamber's own slope); v and y are the end-of-step mechanical state."""
    pa, pb = state[S_PA], state[S_PB]
    rate_a, rate_b, slope_a, slope_b = pressure_rates(y, v, pa, pb, state[S_SPOOL], ps, hp, ports, seal_leak)
    p_min = hp[HP_P_MIN]
    state[S_PA] = max(pa + h * rate_a / (1.0 - h * slope_a), p_min)
    state[S_PB] = max(pb + h * rate_b / (1.0 - h * slope_b), p_min)


SUPPLY_PRESSURE = Key("supply_pressure_bar", 1.0, 400.0, BAR)     # the power unit's, above the atmosphere
TANK_PRESSURE = Key("tank_pressure_bar", 0.0, 10.0, BAR)


@frozen
class ValveSection(Section):
    """The servo-valve's orifices and spool (eq. 4.2-4.6): a [valve] table's keys."""
    edge_flow_m3_s: float = key("edge_flow_l_min", 0.01, 100.0, si=L_MIN)   # per edge, fully open, at edge_drop
    edge_drop_pa: float = key("edge_drop_bar", 1.0, 350.0, si=BAR)
    supply_lap: float = key("supply_lap_pct", 0.0, 50.0, per=100.0)            # underlaps, fraction of the stroke
    return_lap: float = key("return_lap_pct", 0.0, 50.0, per=100.0)
    spool_time_constant_s: float = key("spool_time_constant_ms", 0.05, 100.0, si=1e-3)
    laminar_pa: float = key("laminar_bar", 1e-4, 1.0, si=BAR)


@frozen
class ChamberSection(Section):
    """The cylinder's chambers and hoses (eq. 4.7-4.14): a [chambers] table's keys."""
    dead_volume_a_m3: float = key("dead_volume_a_cm3", 0.1, 5000.0, si=CM3)
    dead_volume_b_m3: float = key("dead_volume_b_cm3", 0.1, 5000.0, si=CM3)
    oil_bulk_modulus_pa: float = key("oil_bulk_modulus_bar", 1000.0, 30000.0, si=BAR)
    air_fraction: float = key("air_fraction_pct", 0.0, 50.0, per=100.0)
    air_polytropic_index: float = key("air_polytropic_index", 1.0, 1.4)
    hose_bulk_modulus_pa: float = key("hose_bulk_modulus_bar", 10.0, 1e6, si=BAR)
    cross_leakage_m3_s_pa: float = key("cross_leakage_l_min_per_bar", 0.0, 10.0, si=L_MIN, per=BAR)
    seal_leakage_m3_s_pa: float = key("seal_leakage_l_min_per_bar", 0.0, 10.0, si=L_MIN, per=BAR)
    min_pressure_pa: float = key("min_pressure_bar", -1.0, 0.0, si=BAR)


def pack(cylinder, valve: ValveSection, chambers: ChamberSection, tank_pa: float) -> np.ndarray:
    """The parameter vector of one actuator: its cylinder (`physics.actuator.CylinderSection`),
    valve and chambers, and the return line's pressure."""
    hp = np.zeros(HP_SIZE)
    hp[HP_AREA_A], hp[HP_ALPHA] = cylinder.piston_area_m2, cylinder.area_ratio
    hp[HP_STROKE] = cylinder.stroke_m
    hp[HP_VA0] = chambers.dead_volume_a_m3
    hp[HP_VB0] = chambers.dead_volume_b_m3
    hp[HP_BETA_OIL] = chambers.oil_bulk_modulus_pa
    hp[HP_AIR0] = chambers.air_fraction
    hp[HP_POLY_N] = chambers.air_polytropic_index
    hp[HP_BETA_WALL] = chambers.hose_bulk_modulus_pa
    hp[HP_KV] = valve.edge_flow_m3_s / math.sqrt(valve.edge_drop_pa)
    hp[HP_LAP_P] = valve.supply_lap
    hp[HP_LAP_T] = valve.return_lap
    hp[HP_LEAK] = chambers.cross_leakage_m3_s_pa
    hp[HP_SEAL_LEAK] = chambers.seal_leakage_m3_s_pa
    hp[HP_TANK] = tank_pa
    hp[HP_LAMINAR] = valve.laminar_pa
    hp[HP_TAU_SPOOL] = valve.spool_time_constant_s
    hp[HP_P_MIN] = chambers.min_pressure_pa
    return hp


STEADY_SPOOL_UNIT = 1e-3     # the steady-state solver's spool variable, per unit of it


def supply_similarity(supply_pa: float, derived_at_pa: float) -> tuple[float, float]:
    """(force factor r, velocity factor sqrt(r)), r = supply_pa / derived_at_pa: through
    turbulent orifices (eq. 4.3) the spool that holds a leg at force F and velocity v at one
    supply holds r F at sqrt(r) v at r times that supply, every pressure r times; exact without
    the tank pressure, the leakage and the cavitation floor (within ~1 % of the spool here)."""
    ratio = supply_pa / derived_at_pa
    return ratio, math.sqrt(ratio)


def steady_state(y: float, force_n: float, ps: float, hp: np.ndarray, velocity_m_s: float = 0.0,
                 guess=None) -> tuple[float, float, float, bool]:
    """Chamber pressures PA, PB [Pa] and the spool [fraction] at which the chambers hold
    still (eq. 4.7-4.8 with both rates 0) at stroke `y`, piston velocity `velocity_m_s` and
    hydraulic force `force_n` (eq. 4.15): at rest, the spool offset that holds the load.
    `guess` (PA, PB [Pa], spool) starts the solver. Returns (PA, PB, spool, converged)."""
    from scipy.optimize import fsolve
    hold = force_n / hp[HP_AREA_A]                      # load pressure PA - alpha PB

    def residual(q):
        pa, pb, spool = q[0] * BAR, q[1] * BAR, q[2] * STEADY_SPOOL_UNIT
        rate_a, rate_b, _, _ = pressure_rates(y, velocity_m_s, pa, pb, spool, ps, hp, 1.0, hp[HP_SEAL_LEAK])
        va, vb = chamber_volumes(y, hp)
        return [(pa - hp[HP_ALPHA] * pb - hold) / BAR,
                rate_a * va / bulk_modulus(pa, hp) * 1e6 / hp[HP_AREA_A],
                rate_b * vb / bulk_modulus(pb, hp) * 1e6 / hp[HP_AREA_A]]

    start = ([(0.5 * ps + hold) / BAR, 0.5 * ps / BAR, 0.0] if guess is None
             else [guess[0] / BAR, guess[1] / BAR, guess[2] / STEADY_SPOOL_UNIT])
    solution, _, ier, _ = fsolve(residual, start, full_output=True, xtol=1e-12)
    converged = ier == 1 and np.max(np.abs(residual(solution))) < 1e-6
    return solution[0] * BAR, solution[1] * BAR, solution[2] * STEADY_SPOOL_UNIT, bool(converged)


def resting_pressures(y: float, force_n: float, ps: float, hp: np.ndarray) -> tuple[float, float]:
    """Where a leg's chambers stand behind its closed load-holding valves after its valve
    held it at rest (the steady state, `steady_state`); where the supply cannot hold the
    force, `holding_pressures`."""
    pa, pb, _, ok = steady_state(y, force_n, ps, hp)
    if ok and hp[HP_P_MIN] <= min(pa, pb) and max(pa, pb) <= ps:
        return pa, pb
    return holding_pressures(force_n, ps, hp)


def holding_pressures(force_n: float, ps: float, hp: np.ndarray) -> tuple[float, float]:
    """Chamber pressures that hold `force_n` on the piston with PA + PB = supply + tank
    (`resting_pressures` where the supply cannot hold the force; plain Python: only a rig's
    start calls it)."""
    alpha = hp[HP_ALPHA]
    load_pressure = force_n / hp[HP_AREA_A]
    pb = (ps + hp[HP_TANK] - load_pressure) / (1.0 + alpha)
    return load_pressure + alpha * pb, pb


def force_capacity(velocity_m_s: float, ps: float, hp: np.ndarray) -> tuple[float, float]:
    """The hydraulic force range (eq. 4.15) a leg gives at piston velocity `velocity_m_s`
    with its valve fully open each way: the chambers' steady state (eq. 4.7-4.8, both rates
    0, the leakage included) at spool +1 (the largest force, extending positive) and at -1
    (the smallest). NaN for a side on which that opening cannot move the piston so fast (a
    chamber would have to leave [cavitation floor, supply]). Steady pressures do not depend
    on the chamber volumes, so this holds at any stroke."""
    from scipy.optimize import fsolve
    area, alpha = hp[HP_AREA_A], hp[HP_ALPHA]

    def side(spool: float) -> float:
        def residual(q):
            pa, pb = q[0] * BAR, q[1] * BAR
            qa, qb, _, _ = valve_flows(spool, pa, pb, ps, hp)
            leak = (hp[HP_LEAK] + hp[HP_SEAL_LEAK]) * (pa - pb)
            return [(qa - leak - area * velocity_m_s) * 1e6 / area,
                    (qb + leak + alpha * area * velocity_m_s) * 1e6 / area]

        # the side the open spool pressurises starts near the supply, the other near the tank
        start = [0.9 * ps / BAR, 0.1 * ps / BAR] if spool > 0.0 else [0.1 * ps / BAR, 0.9 * ps / BAR]
        solution, _, ier, _ = fsolve(residual, start, full_output=True, xtol=1e-12)
        pa, pb = solution[0] * BAR, solution[1] * BAR
        inside = hp[HP_P_MIN] - 1.0 <= min(pa, pb) and max(pa, pb) <= ps + 1.0
        if ier != 1 or max(abs(r) for r in residual(solution)) > 1e-6 or not inside:
            return math.nan
        return float(piston_force(pa, pb, hp))

    return side(1.0), side(-1.0)


def capacity_table(velocities_m_s: np.ndarray, ps: float, hp: np.ndarray) -> np.ndarray:
    """`force_capacity` over a velocity grid: (len, 2) of (largest, smallest) force [N]. A
    leg braking (pushing while it retracts, pulling while it extends) drives oil back toward
    the supply; the relief above it is not modelled, so that side is taken as at rest (a lower
    bound). What stays NaN is a speed the open valve cannot reach."""
    table = np.array([force_capacity(float(v), ps, hp) for v in velocities_m_s])
    push_rest, pull_rest = force_capacity(0.0, ps, hp)
    braking_push = (velocities_m_s < 0.0) & np.isnan(table[:, 0])
    braking_pull = (velocities_m_s > 0.0) & np.isnan(table[:, 1])
    table[braking_push, 0] = push_rest
    table[braking_pull, 1] = pull_rest
    return table
