"""Model-based residuals of the actuators (beyond the thesis): each leg's chamber pressures
predicted from its valve command and its encoder (eq. 4.2-4.10 with the controller's own
parameters of the actuator) against the force its load cell measures.

Per leg, every cycle while its valve is ACTIVE:
    p_A, p_B  <- continuity (eq. 4.7-4.8): the valve's flows at the spool applied at this
                 SYNC, the piston's swept volume from the encoder's displacement (its counts
                 do not accumulate: the swept volume telescopes)
    F_model    = A (p_A - alpha p_B)                                     (eq. 4.15)
    F_piston   = F_load cell + m_rod (g_axial + a) + sigma2 v, v the encoder's rate, a the
                 Kalman filter's acceleration (the rod's balance)
    e          = F_piston - F_model; p_A, p_B corrected by `gain` e (the level p_A + p_B is
                 not seen by the force: a LEG_PRESSURE sample sets it, the model keeping its
                 own p_A - alpha p_B, so a fault's force error is not wiped)
    r          = low-pass(e)
The seals' Coulomb and Stribeck friction is left out of F_piston (its sign is unknown while
the encoder's velocity crosses zero) and is the threshold's floor instead:
    threshold  = max(|alpha0 + alpha1|) (Tables 6.1-6.2) + K q / 2 + spread K T / gain <|Q / A|>
with K the oil column's stiffness, q the encoder's count, `spread` the flow gain's relative
spread over Table A.3 (k01), Q the model's valve flow and <.> the larger of its present value
and its average with weight `gain` per cycle: a flow error e_k = spread K T |Q/A|_k, corrected
by `gain` each cycle, sums to at most spread K T / gain times that average. A leg whose |r|
stays above it for `persistence` cycles is faulty (several legs at once point at the supply).
What it sees: a valve that does not follow its command, a seized rod, a lost supply, a
frozen encoder. Allocation-free on arrays made here.

Per valve, its reported spool (LEG_STATE's SPOOL) against where the spool's first-order lag
(`HP_TAU_SPOOL`) takes its previous report under the command it applied over the period:
    x_pred     = u + (x_prev - u) exp(-T / tau)
    threshold  = floor + |u - x_prev| max|exp(-T / tau') - exp(-T / tau)|, tau' = tau (1 -+ spread)
A command that reached the valve after its SYNC is applied a period late, so the residual
is the smaller of the two candidates (this period's command and the one before). A jammed
spool is off by its jam at the first report; the force residual sees it only through the
flow it causes.

Per leg, its chambers predicted from one LEG_PRESSURE sample to the next (every 16th cycle):
the same continuity laws from the sampled p_A, p_B, driven by the applied spool and the
encoder's swept volume only (no force enters them, so the seals' friction does not either),
run nominal, with each uncertain parameter at the edge of its spread over Table A.3 (the
flow gain k01 both ways, the leakage as b1's, the stiffness as b0's), and nominal on the
command before the applied one (which command the valve applied is known only to a cycle):
    d_X        = p_X,sample - p_X,predicted                              X = A, B
    threshold  = sum over the parameters j of |p_X,j - p_X,nominal| + beta_X / V_X A_X q + floor
    ratio      = the smaller over the two commands of max_X |d_X| / threshold
    evidence   = ratio + max(0, the ratio at the leg's sample before - carry)
with A_X the area on chamber X (A, alpha A), q the encoder's count and `floor` the two
samples' noise and wire steps: a count of swept volume through the chamber's stiffness, as the
reading's error swings by q when the count steps. A leg is faulty when its evidence passes 1: one
sample beyond, or two in a row whose ratios sum past 1 + carry. A fault's first sample sees the
chambers' jump at its onset, the next the offset that stays; where the onset falls just before a
sample the first sees little, so a fault near the threshold needs the two together. A model error
held under (1 + carry) / 2 of its bound is no fault. What it sees: flow between the chambers the
model has no path for (a leaking piston seal pulls p_A and p_B together), a chamber
transducer gone wrong.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from physics import hydraulics as hy
from physics import lugre

FRICTION_SIDES = ((lugre.A0_POS, lugre.A1_POS), (lugre.A0_NEG, lugre.A1_NEG))


def breakaway_force_n(fp: np.ndarray) -> float:
    """The seals' largest static friction |alpha0 + alpha1| over both sides."""
    return max(abs(fp[a0] + fp[a1]) for a0, a1 in FRICTION_SIDES)


@njit(cache=True)
def residual_step(hp, fp, ps, period_s, substeps, spool_applied, fresh, position, force, gravity_axial,
                  accel, rod_mass, gain, alpha_lp, pressure_fresh, pa_meas, pb_meas, state, seeded, y_prev, stale,
                  residual, flow_velocity) -> None:
    """One cycle of every leg's chamber model on its valve's supply `ps[i]` (the P-port
    transducer's latest sample); writes `residual` (low-passed force error, N)
    and `flow_velocity` (the model's valve flow into A over the piston area, m/s). A leg
    without a fresh frame keeps its residual; its chambers follow the spool at the last
    position, and the next frame's displacement is swept in one cycle (volumes telescope).
    A leg not `seeded` waits for its first pressure sample (no level, no model)."""
    area, ratio = hp[hy.HP_AREA_A], hp[hy.HP_ALPHA]
    h = period_s / substeps
    decay = hy.spool_decay(h, hp)
    for i in range(position.shape[0]):
        row = state[i]
        if not seeded[i]:
            if fresh[i] and pressure_fresh[i]:
                row[hy.S_PA], row[hy.S_PB], row[hy.S_SPOOL] = pa_meas[i], pb_meas[i], spool_applied[i]
                y_prev[i] = position[i]
                stale[i] = 0
                seeded[i] = True
            continue
        if fresh[i]:
            dy = position[i] - y_prev[i]
            v = dy / (period_s * (1 + stale[i]))     # the rate over the time it took
            stale[i] = 0
        else:
            dy, v = 0.0, 0.0
            stale[i] += 1
        for j in range(substeps):
            row[hy.S_SPOOL] = hy.spool_lag(row[hy.S_SPOOL], spool_applied[i], decay)
            hy.chamber_step(row, y_prev[i] + dy * (j + 1) / substeps, dy / period_s, ps[i], h, hp, 1.0,
                            hp[hy.HP_SEAL_LEAK])
        if not fresh[i]:
            continue
        y_prev[i] = position[i]
        if pressure_fresh[i]:                        # the sample's level p_A + p_B, the model's force
            load = row[hy.S_PA] - ratio * row[hy.S_PB]
            row[hy.S_PB] = (pa_meas[i] + pb_meas[i] - load) / (1.0 + ratio)
            row[hy.S_PA] = load + ratio * row[hy.S_PB]
        qa, _, _, _ = hy.valve_flows(row[hy.S_SPOOL], row[hy.S_PA], row[hy.S_PB], ps[i], hp)
        flow_velocity[i] = qa / area
        _, sigma2 = lugre.stribeck(v, fp)           # the encoder's own rate: an estimator lags a fast start
        piston = force[i] + rod_mass * (gravity_axial[i] + accel[i]) + sigma2 * v
        error = piston - hy.piston_force(row[hy.S_PA], row[hy.S_PB], hp)
        correction = gain * error / (area * (1.0 + ratio))
        row[hy.S_PA] += correction
        row[hy.S_PB] -= correction
        residual[i] += alpha_lp * (error - residual[i])


@njit(cache=True)
def residual_verdict(residual, flow_velocity, flow_bound, gain, floor_n, flow_n_per_m_s, persistence, above, ratio):
    """Persistence per leg; returns (legs faulty, the worst faulty leg, the largest ratio),
    ratio[i] the leg's |r| / threshold this cycle. Once one leg is faulty, every leg beyond
    its threshold this cycle counts: a supply fault reaches them all, not all in one cycle."""
    persisted, worst, worst_ratio, peak, beyond = 0, -1, 0.0, 0.0, 0
    for i in range(residual.shape[0]):
        # the flow error a correction of `gain` per cycle leaves: the same average of |Q / A|
        # (after the flow falls), and at least its present value (the step's own error)
        flow_bound[i] += gain * (abs(flow_velocity[i]) - flow_bound[i])
        threshold = floor_n + flow_n_per_m_s * max(flow_bound[i], abs(flow_velocity[i]))
        ratio[i] = abs(residual[i]) / threshold
        peak = max(peak, ratio[i])
        above[i] = above[i] + 1 if ratio[i] > 1.0 else 0
        if above[i] > 0:
            beyond += 1
        if above[i] >= persistence:
            persisted += 1
            if ratio[i] > worst_ratio:
                worst, worst_ratio = i, ratio[i]
    return (beyond if persisted else 0), worst, peak


@njit(cache=True)
def start_state(pressure_valid, pa_meas, pb_meas, position, state, seeded, y_prev, stale, residual, above) -> None:
    """The chambers where the transducers last saw them; a leg whose transducers have not
    spoken waits for its first sample: the chambers' level sets the valve's flows, and where
    they rest depends on the supply and on what the leg went through."""
    for i in range(position.shape[0]):
        row = state[i]
        seeded[i] = pressure_valid[i]
        row[hy.S_PA], row[hy.S_PB] = pa_meas[i], pb_meas[i]
        row[hy.S_SPOOL] = 0.0
        y_prev[i] = position[i]
        stale[i] = 0
        residual[i] = 0.0
        above[i] = 0


class ActuatorResiduals:
    """The residual of every leg. `start(...)` when its valves go ACTIVE, `update(...)` every
    cycle after; `legs_faulty`, `worst_leg` (-1: none), `ratio` (|r| / threshold) and `peak`
    (its largest) say what it saw."""

    def __init__(self, n_legs: int, hp: np.ndarray, friction: np.ndarray, period_s: float,
                 rod_mass_kg: float, stiffness_n_m: float, encoder_m: float, gain: float, filter_s: float,
                 persistence: int, flow_spread: float, substeps: int = 2):
        self.hp, self.friction, self.period_s = hp, friction, period_s
        self.rod_mass, self.gain, self.persistence, self.substeps = rod_mass_kg, gain, persistence, substeps
        self.alpha_lp = 1.0 - math.exp(-period_s / filter_s)
        self.floor_n = breakaway_force_n(friction) + 0.5 * stiffness_n_m * encoder_m
        self.flow_n_per_m_s = flow_spread * stiffness_n_m * period_s / gain
        self.state = np.zeros((n_legs, hy.S_SIZE))
        self.seeded = np.zeros(n_legs, dtype=np.bool_)      # the leg's chambers started from a sample
        self.y_prev = np.zeros(n_legs)
        self.stale = np.zeros(n_legs, dtype=np.int64)       # cycles since the leg's last fresh frame
        self.residual = np.zeros(n_legs)
        self.flow_velocity = np.zeros(n_legs)
        self.flow_bound = np.zeros(n_legs)                  # |Q / A| averaged as the correction forgets
        self.ratio = np.zeros(n_legs)
        self.above = np.zeros(n_legs, dtype=np.int64)
        self.legs_faulty, self.worst_leg, self.peak = 0, -1, 0.0

    def start(self, position_m, pressure_valid, pa_pa, pb_pa) -> None:
        start_state(pressure_valid, pa_pa, pb_pa, position_m, self.state, self.seeded, self.y_prev, self.stale,
                    self.residual, self.above)
        self.flow_bound.fill(0.0)
        self.legs_faulty, self.worst_leg = 0, -1

    def update(self, spool_applied, fresh, position_m, force_n, gravity_axial, accel_m_s2, pressure_fresh, pa_pa,
               pb_pa, supply_pa) -> int:
        """One cycle: `spool_applied` the spool each valve applied over the period the
        measurements close, `supply_pa` each valve's supply. Returns 0, or once a leg's
        residual has persisted beyond its threshold, the number of legs beyond theirs this cycle."""
        residual_step(self.hp, self.friction, supply_pa, self.period_s, self.substeps, spool_applied, fresh,
                      position_m, force_n, gravity_axial, accel_m_s2, self.rod_mass, self.gain, self.alpha_lp,
                      pressure_fresh, pa_pa, pb_pa, self.state, self.seeded, self.y_prev, self.stale,
                      self.residual, self.flow_velocity)
        self.legs_faulty, self.worst_leg, self.peak = residual_verdict(self.residual, self.flow_velocity,
                                                                       self.flow_bound, self.gain, self.floor_n,
                                                            self.flow_n_per_m_s, self.persistence, self.above,
                                                            self.ratio)
        return self.legs_faulty


@njit(cache=True)
def spool_step_check(hp, period_s, applied, applied_late, spool, fresh, valve_state, active_state, floor, lag_spread,
                     persistence, seeded, spool_prev, above, ratio):
    """One cycle of every valve's spool residual; returns (legs faulty, the worst faulty leg,
    the largest ratio). A leg without a fresh frame, or whose valve is not ACTIVE, starts
    again from its next report."""
    decay = math.exp(-period_s / hp[hy.HP_TAU_SPOOL])
    persisted, worst, worst_ratio, peak = 0, -1, 0.0, 0.0
    for i in range(spool.shape[0]):
        if not (fresh[i] and valve_state[i] == active_state):
            seeded[i], above[i], ratio[i] = False, 0, 0.0
            continue
        if not seeded[i]:
            seeded[i], spool_prev[i], above[i], ratio[i] = True, spool[i], 0, 0.0
            continue
        best = math.inf
        for u in (applied[i], applied_late[i]):
            target = min(max(u, -1.0), 1.0)
            gap = target - spool_prev[i]
            best = min(best, abs(spool[i] - (target - gap * decay)) / (floor + abs(gap) * lag_spread))
        ratio[i] = best
        spool_prev[i] = spool[i]
        peak = max(peak, best)
        above[i] = above[i] + 1 if best > 1.0 else 0
        if above[i] >= persistence:
            persisted += 1
            if best > worst_ratio:
                worst, worst_ratio = i, best
    return persisted, worst, peak


def lag_uncertainty(period_s: float, tau_s: float, spread: float) -> float:
    """The largest change of the lag's one-period decay exp(-T / tau) over tau (1 -+ spread)."""
    nominal = math.exp(-period_s / tau_s)
    return max(abs(math.exp(-period_s / (tau_s * (1.0 + s))) - nominal) for s in (-spread, spread))


class SpoolResidual:
    """Every valve's spool residual. `start()` when the valves go ACTIVE, `update(...)` every
    cycle after; `legs_faulty`, `worst_leg` (-1: none), `ratio` and `peak` as for the chambers."""

    def __init__(self, n_legs: int, hp: np.ndarray, period_s: float, floor: float, lag_spread: float,
                 persistence: int, active_state: int):
        self.hp, self.period_s, self.floor, self.persistence = hp, period_s, floor, persistence
        self.active_state = active_state
        self.lag_spread = lag_uncertainty(period_s, float(hp[hy.HP_TAU_SPOOL]), lag_spread)
        self.seeded = np.zeros(n_legs, dtype=np.bool_)
        self.spool_prev = np.zeros(n_legs)
        self.above = np.zeros(n_legs, dtype=np.int64)
        self.ratio = np.zeros(n_legs)
        self.legs_faulty, self.worst_leg, self.peak = 0, -1, 0.0

    def start(self) -> None:
        self.seeded.fill(False)
        self.above.fill(0)
        self.legs_faulty, self.worst_leg = 0, -1

    def update(self, applied, applied_late, spool, fresh, valve_state) -> int:
        """`applied` the setpoint each valve applied over the period the reports close (sent
        two cycles before), `applied_late` the one before it. Returns the legs faulty."""
        self.legs_faulty, self.worst_leg, self.peak = spool_step_check(
            self.hp, self.period_s, applied, applied_late, spool, fresh, valve_state, self.active_state, self.floor,
            self.lag_spread, self.persistence, self.seeded, self.spool_prev, self.above, self.ratio)
        return self.legs_faulty


PRESSURE_SIGMAS = 6.0      # a pair of samples' noise beyond this many of its sigmas: p < 2e-9
# the chamber prediction's models: the prediction, and in coarse steps the nominal reference,
# one model per uncertain parameter (flow gain both ways, leakage, stiffness) and the nominal
# driven by the command before (a command that reached its valve after the SYNC, or sensor
# frames a cycle late: which one was applied over a period is known only to a cycle)
PRED_NOMINAL, PRED_REFERENCE, PRED_FLOW_LOW, PRED_FLOW_HIGH, PRED_LEAKAGE, PRED_STIFFNESS, PRED_LATE = range(7)
# 16 steps of 125 us resolve the chambers with the spool open: under computed torque's force
# loop ringing at rest (36 Hz, spool +-17 to +-75 %) 8 steps reached 0.60 of the threshold, 16
# 0.42 (log replays); the spreads are differences of models stepped alike, 2 steps suffice
PRED_FINE_STEPS = 16
PRED_COARSE_STEPS = 2       # constants, not arguments: called with 20, numba's dispatcher kept ~200 B a call
# a prediction spans at least the hexapod's LEG_PRESSURE period: where samples come every cycle
# (the test bench) a one-cycle prediction is all quantisation, up to the count's whole term
PRED_INTERVAL_CYCLES = 16
NOT_JUDGED = -1.0           # a leg's ratio in a cycle without a judged sample of it


def sample_floor_pa(noise_pa: float, wire_step_pa: float) -> float:
    """The prediction's floor: the start and end samples' noise (sqrt 2 of one) to
    PRESSURE_SIGMAS, and half the wire's step at each end."""
    return PRESSURE_SIGMAS * math.sqrt(2.0) * noise_pa + wire_step_pa


@njit(cache=True)
def predict_chambers(row, hp, spool, y_start, dy, ps, period_s, steps):
    """One period of one leg's chambers in `steps` steps, the piston swept by `dy`."""
    h = period_s / steps
    decay = hy.spool_decay(h, hp)
    for j in range(steps):
        row[hy.S_SPOOL] = hy.spool_lag(row[hy.S_SPOOL], spool, decay)
        hy.chamber_step(row, y_start + dy * (j + 1) / steps, dy / period_s, ps, h, hp, 1.0, hp[hy.HP_SEAL_LEAK])


@njit(cache=True)
def pressure_prediction_step(models, ps, period_s, spool_applied, spool_late, fresh, position, valve_state,
                             active_state, pressure_fresh, pa_meas, pb_meas, floor_pa, encoder_m, state, y_prev,
                             age, ratio, supply_like) -> None:
    """One cycle of every leg's sample-to-sample chamber prediction on its valve's supply
    `ps[i]` (the P-port transducer's latest sample): `models` the parameter
    vectors (PRED_* rows), `state[m, i]` leg i under model m; the prediction in
    PRED_FINE_STEPS per cycle, the parameters' spreads as differences of models all in
    PRED_COARSE_STEPS (their integration error cancels in the difference); PRED_LATE is
    driven by `spool_late`, the command before `spool_applied`. At a leg's LEG_PRESSURE
    sample writes `ratio[i]` (largest |d_X| / threshold of the nearer candidate; -1 where no
    sample was judged) and `supply_like[i]` (both chambers beyond on one side), and starts
    again from the sample; `age[i]` counts the cycles since (-1: not
    started), and samples before PRED_INTERVAL_CYCLES are passed over. A leg without a fresh
    frame, or whose valve is not ACTIVE (its load-holding valves shut), starts again from its
    next sample."""
    n_models = models.shape[0]
    for i in range(position.shape[0]):
        ratio[i] = NOT_JUDGED
        # the piston moves only as far as the reading demands: the true position is within half
        # a count of it, so a reading dithering between two counts sweeps nothing
        dy = 0.0
        if fresh[i]:
            half = 0.5 * encoder_m
            dy = min(max(y_prev[i], position[i] - half), position[i] + half) - y_prev[i]
        predict_chambers(state[PRED_NOMINAL, i], models[PRED_NOMINAL], spool_applied[i], y_prev[i], dy, ps[i], period_s,
                         PRED_FINE_STEPS)
        for m in range(PRED_REFERENCE, n_models):
            spool = spool_late[i] if m == PRED_LATE else spool_applied[i]
            predict_chambers(state[m, i], models[m], spool, y_prev[i], dy, ps[i], period_s, PRED_COARSE_STEPS)
        y_prev[i] += dy
        if not (fresh[i] and valve_state[i] == active_state):
            age[i] = -1
            continue
        if age[i] >= 0:
            age[i] += 1
        if not pressure_fresh[i] or 0 <= age[i] < PRED_INTERVAL_CYCLES:
            continue
        if age[i] >= 0:
            hp = models[0]
            va, vb = hy.chamber_volumes(position[i], hp)
            swept = encoder_m * hp[hy.HP_AREA_A]          # a count: the reading's error swings by q at a step
            # two candidates: the applied command (r0) and the one before (r1: the late model's
            # difference to the coarse reference moved onto the fine prediction); the nearer counts
            worst0, worst1, low0, high0, low1, high1 = 0.0, 0.0, 0, 0, 0, 0
            for s_col, meas, volume, area_ratio in ((hy.S_PA, pa_meas[i], va, 1.0),
                                                   (hy.S_PB, pb_meas[i], vb, hp[hy.HP_ALPHA])):
                reference = state[PRED_REFERENCE, i, s_col]
                spread = (max(abs(state[PRED_FLOW_LOW, i, s_col] - reference),
                              abs(state[PRED_FLOW_HIGH, i, s_col] - reference))
                          + abs(state[PRED_LEAKAGE, i, s_col] - reference)
                          + abs(state[PRED_STIFFNESS, i, s_col] - reference))
                threshold = spread + hy.bulk_modulus(meas, hp) / volume * area_ratio * swept + floor_pa
                r0 = (meas - state[PRED_NOMINAL, i, s_col]) / threshold
                r1 = r0 - (state[PRED_LATE, i, s_col] - reference) / threshold
                worst0, worst1 = max(worst0, abs(r0)), max(worst1, abs(r1))
                low0, high0 = low0 + (r0 < -1.0), high0 + (r0 > 1.0)
                low1, high1 = low1 + (r1 < -1.0), high1 + (r1 > 1.0)
            worst, low, high = (worst0, low0, high0) if worst0 <= worst1 else (worst1, low1, high1)
            ratio[i] = worst
            # both chambers beyond on the same side: the valve's inflow changed, the supply's kind;
            # flow from one chamber into the other (a seal) or one transducer is the leg's own
            supply_like[i] = low == 2 or high == 2
        for m in range(n_models):
            state[m, i, hy.S_PA], state[m, i, hy.S_PB] = pa_meas[i], pb_meas[i]
        age[i] = 0


class ChamberPrediction:
    """Every leg's chambers predicted from one LEG_PRESSURE sample to the next. `start()` when
    the valves go ACTIVE, `update(...)` every cycle after; `legs_faulty`, `worst_leg` (-1:
    none), `ratio` (at the leg's sample) and `peak` (the cycle's largest) as for the others.
    `evidence` (the ratio with the excess over `carry` of the leg's sample before)
    and `peak` (the cycle's largest evidence) as for the others. A leg is faulty after
    `persistence` samples whose evidence is beyond in a row."""

    def __init__(self, n_legs: int, hp: np.ndarray, period_s: float, encoder_m: float,
                 flow_spread: float, leakage_spread: float, stiffness_spread: float, floor_pa: float,
                 persistence: int, carry: float, active_state: int):
        self.period_s, self.encoder_m = period_s, encoder_m
        self.active_state = active_state
        self.floor_pa, self.persistence, self.carry = floor_pa, persistence, carry
        self.models = np.tile(hp, (PRED_LATE + 1, 1))
        self.models[PRED_FLOW_LOW, hy.HP_KV] *= 1.0 - flow_spread
        self.models[PRED_FLOW_HIGH, hy.HP_KV] *= 1.0 + flow_spread
        self.models[PRED_LEAKAGE, [hy.HP_LEAK, hy.HP_SEAL_LEAK]] *= 1.0 + leakage_spread
        self.models[PRED_STIFFNESS, [hy.HP_BETA_OIL, hy.HP_BETA_WALL]] *= 1.0 - stiffness_spread
        self.state = np.zeros((PRED_LATE + 1, n_legs, hy.S_SIZE))
        self.y_prev = np.zeros(n_legs)
        self.age = np.full(n_legs, -1, dtype=np.int64)     # cycles since the prediction's sample
        self.ratio = np.zeros(n_legs)
        self.last = np.zeros(n_legs)             # each leg's ratio at its judged sample before
        self.evidence = np.zeros(n_legs)
        self.supply_like = np.zeros(n_legs, dtype=np.bool_)
        self.above = np.zeros(n_legs, dtype=np.int64)
        self.legs_faulty, self.worst_leg, self.peak = 0, -1, 0.0

    def start(self, position_m: np.ndarray) -> None:
        self.state[:, :, hy.S_SPOOL].fill(0.0)
        self.y_prev[:] = position_m
        self.age.fill(-1)
        self.last.fill(0.0)
        self.evidence.fill(0.0)
        self.above.fill(0)
        self.legs_faulty, self.worst_leg = 0, -1

    def update(self, spool_applied, spool_late, fresh, position_m, valve_state, pressure_fresh, pa_pa, pb_pa,
               supply_pa) -> int:
        """`spool_applied`, `spool_late` as for `SpoolResidual.update`, `supply_pa` each valve's
        supply. Returns the legs faulty."""
        pressure_prediction_step(self.models, supply_pa, self.period_s, spool_applied, spool_late, fresh,
                                 position_m, valve_state, self.active_state, pressure_fresh, pa_pa, pb_pa,
                                 self.floor_pa, self.encoder_m, self.state, self.y_prev, self.age, self.ratio,
                                 self.supply_like)
        self.legs_faulty, self.worst_leg, self.peak = sample_verdict(self.ratio, self.supply_like, self.age,
                                                                     self.carry, self.persistence, self.last,
                                                                     self.evidence, self.above)
        return self.legs_faulty


@njit(cache=True)
def sample_verdict(ratio, supply_like, age, carry, persistence, last, evidence, above):
    """Each judged sample's evidence (its ratio and the excess over `carry` of the leg's
    ratio before, `last`; a leg whose prediction broke off, `age` -1, has none before),
    persistence over the samples; returns (legs faulty, the worst of them whose last sample
    was the leg's own kind, or -1: legs of the supply's kind count only toward the supply;
    the cycle's largest evidence)."""
    persisted, worst, worst_evidence, peak = 0, -1, -1.0, 0.0
    for i in range(ratio.shape[0]):
        if age[i] < 0:
            last[i] = 0.0
        if ratio[i] != NOT_JUDGED:
            evidence[i] = ratio[i] + max(0.0, last[i] - carry)
            last[i] = ratio[i]
            above[i] = above[i] + 1 if evidence[i] > 1.0 else 0
            peak = max(peak, evidence[i])
        if above[i] >= persistence:
            persisted += 1
            if not supply_like[i] and evidence[i] > worst_evidence:
                worst, worst_evidence = i, evidence[i]
    return persisted, worst, peak
