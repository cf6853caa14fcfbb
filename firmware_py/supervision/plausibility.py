"""Plausibility of the measurements: commanded against measured motion per leg, the
legs' platform attitude against the IMU's, load cells that stop changing, and the valves'
supply transducers against the supply the actuator model assumes.

MotionPlausibility, commanded against measured motion, per leg: a valve that is driven hard must move its
cylinder. It catches what the other limits only see late or never: a stuck encoder (the
reference runs away from a frozen reading), a seized rod, a lost supply pressure (the legs
sink while the valves push them up).

Rule: while the valve input stays beyond `spool_min` (fraction of full input) with one sign for
`window` cycles, the encoder must advance at least `travel_min` in that direction from the
furthest point back it reached in the window; a window without it is implausible. A leg whose
load cell shows `overrun_share` of the force its valve gives fully open that way at its
velocity (`supervision.capacity`'s table) is held back by its load, not failing to move: its
window starts again (a payload's corner pulls a leg back through its reversal at its limit).
Defaults (controller.toml): on the hexapod 30 % input for 0.2 s, 0.5 mm (4 encoder counts):
its legs (190-260 kg of joint-space inertia) tripped a 10 %, 50 ms window in the chapter
11 movements, and they hold the platform's weight at > 10 % input without moving. On the
test bench ([testbench]) 5 % for 50 ms: its horizontal slide holds no static load, and 10 %
moves the cylinder at 225-295 mm/s unloaded (k01 of Table A.3 x 1 V). In place on arrays
made at construction (no allocation per cycle).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from firmware_py.mechanics.rotation import angle_between_matrices, rpy_to_matrix_into
from firmware_py.motion_control.computed_torque import force_range_at


@njit(cache=True)
def at_capacity(spool, force_n, velocity_m_s, grid_m_s, push_n, pull_n, share) -> bool:
    """A leg's load cell shows `share` of the force its valve gives fully open in the spool's
    direction at its velocity (`force_range_at` at the configured supply)."""
    limit = share * force_range_at(velocity_m_s, 1.0, grid_m_s, push_n, pull_n, spool > 0.0)
    return force_n >= limit if spool > 0.0 else force_n <= limit


@njit(cache=True)
def motion_window(spool, position_m, force_n, velocity_m_s, spool_min, window, travel_min_m, grid_m_s, push_n,
                  pull_n, overrun_share, count, start, sign):
    """One cycle of every leg's motion window; True when a leg completed one without moving
    `travel_min_m` along its command."""
    implausible = False
    for leg in range(spool.shape[0]):
        driven = abs(spool[leg]) >= spool_min and not at_capacity(spool[leg], force_n[leg], velocity_m_s[leg],
                                                                  grid_m_s, push_n, pull_n, overrun_share)
        s = (1.0 if spool[leg] > 0.0 else -1.0) if driven else 0.0
        if s != sign[leg]:                   # a new direction (or none) starts a new window here
            start[leg] = position_m[leg]
            count[leg] = 0
        sign[leg] = s
        if driven:
            count[leg] += 1
        # progress is counted from the furthest point back in the window: a heavy load still
        # coasting the other way after the command reversed is not a failure to move
        progress = (position_m[leg] - start[leg]) * s
        if progress < 0.0:
            start[leg] = position_m[leg]
            progress = 0.0
        if count[leg] >= window:
            if progress < travel_min_m:
                implausible = True
            start[leg] = position_m[leg]     # a completed window starts the next one here
            count[leg] = 0
    return implausible


class MotionPlausibility:
    def __init__(self, n: int, spool_min: float, window: int, travel_min_m: float, capacity, overrun_share: float):
        """`capacity`: the legs' `supervision.capacity.LegCapacity` (its force range over velocity)."""
        self.spool_min, self.window, self.travel_min_m = spool_min, window, travel_min_m
        self.grid_m_s, self.push_n, self.pull_n = capacity.velocities_m_s, capacity.push_n, capacity.pull_n
        self.overrun_share = overrun_share
        self.count = np.zeros(n, dtype=np.int64)        # cycles in the current window
        self.start = np.zeros(n)                         # encoder reading when it began
        self.sign = np.zeros(n)                          # the command's direction in it (0: none)

    def reset(self) -> None:
        self.count.fill(0)
        self.sign.fill(0.0)

    def update(self, spool: np.ndarray, position_m: np.ndarray, force_n: np.ndarray,
               velocity_m_s: np.ndarray) -> bool:
        """One cycle: `spool` the commanded valve input (fraction of full input), `position_m`
        the encoder, `force_n` the load cells, `velocity_m_s` the legs' estimate. True when a
        leg completed a window without moving along its command."""
        return motion_window(spool, position_m, force_n, velocity_m_s, self.spool_min, self.window,
                             self.travel_min_m, self.grid_m_s, self.push_n, self.pull_n, self.overrun_share,
                             self.count, self.start, self.sign)


class AttitudeCrossCheck:
    """The platform's attitude from the six encoders (direct kinematics) against the IMU's.

    Two independent sensors of the same rotation: a leg whose encoder freezes or jumps
    moves the DK attitude away from the IMU's long before the tracking or motion checks
    see it (a frozen encoder under the model-based controller drives its leg at 10-20 %
    input, below the motion window's threshold, and in 0.5 s the platform is 280 mm
    away). `samples` IMU readings in a row beyond `limit_rad` are implausible. Normal
    disagreement: encoder quantisation (0.125 mm over a ~0.2 m lever ~ 0.6 mrad) plus the
    IMU's noise, both far below the default 1 degree.
    """

    def __init__(self, limit_rad: float, samples: int):
        self.limit_rad, self.samples = limit_rad, samples
        self.beyond = 0
        self.angle_rad = 0.0          # the last disagreement, for logs and tests
        self.ratio = 0.0              # ... over the limit (the false-alarm margin's measure)
        self._imu_rot = np.empty((3, 3))
        # load the kernels now: compiled (or read from numba's cache) inside a realtime cycle
        # they would stall the loop past its OVERRUN limit at the first IMU frame
        self.update(np.eye(3), 0.0, 0.0, 0.0)
        self.reset()

    def reset(self) -> None:
        self.beyond = 0
        self.ratio = 0.0

    def update(self, dk_rot: np.ndarray, roll: float, pitch: float, yaw: float) -> bool:
        """One IMU sample against the DK rotation of the same cycle; True when implausible."""
        rpy_to_matrix_into(roll, pitch, yaw, self._imu_rot)
        self.angle_rad = angle_between_matrices(dk_rot, self._imu_rot)
        self.ratio = self.angle_rad / self.limit_rad
        self.beyond = self.beyond + 1 if self.ratio > 1.0 else 0
        return self.beyond >= self.samples


FROZEN_FALSE_ALARM = 1e-9              # a healthy load cell's chance per cycle of looking frozen


def frozen_limit(noise_n: float, lsb_n: float) -> int:
    """Readings in a row, equal to the bit, beyond which a load cell is frozen: one with
    Gaussian noise `noise_n` read at `lsb_n` repeats its last reading with probability
    p = lsb / (2 sqrt(pi) noise) (two draws in one bin), so n repeats have p^n; the least n
    with p^n below FROZEN_FALSE_ALARM. 0 (no check) when the sensor is too quiet to tell."""
    if noise_n <= 0.0:
        return 0
    p = lsb_n / (2.0 * math.sqrt(math.pi) * noise_n)
    return 0 if p >= 0.5 else math.ceil(math.log(FROZEN_FALSE_ALARM) / math.log(p))


@njit(cache=True)
def frozen_step(values, fresh, last, run, limit):
    """Count, per leg, fresh readings equal to the one before; the first leg whose run
    reached `limit`, -1 when none (or limit 0)."""
    faulty = -1
    for i in range(values.shape[0]):
        if not fresh[i]:
            continue
        run[i] = run[i] + 1 if values[i] == last[i] else 0
        last[i] = values[i]
        if limit > 0 and run[i] >= limit and faulty < 0:
            faulty = i
    return faulty


class FrozenLoadCells:
    """A load cell whose reading stops changing (stuck, or dead at zero): its noise makes a
    healthy one change every few cycles. `update` returns the faulty leg or -1."""

    def __init__(self, n_legs: int, noise_n: float, lsb_n: float):
        self.limit = frozen_limit(noise_n, lsb_n)
        self.last = np.full(n_legs, np.nan)
        self.run = np.zeros(n_legs, dtype=np.int64)

    def reset(self) -> None:
        self.last.fill(np.nan)
        self.run.fill(0)

    def update(self, force_n: np.ndarray, fresh: np.ndarray) -> int:
        return frozen_step(force_n, fresh, self.last, self.run, self.limit)


@njit(cache=True)
def supply_step(ps, fresh, tank_pa, drop_pa, flow_spread, ratio, run, legs_needed, latest):
    """Judge each leg's fresh supply sample: the valve's flow goes with the square root of the
    pressure the power unit gives above the tank (the orifice law), so a supply p gives
    sqrt((p - p_T) / (p_S - p_T)) of the model's flow; ratio[i] = |that - 1| / flow_spread, the
    sample beyond the model's flow-gain spread when above 1. Returns (legs whose latest sample
    is beyond, the first leg beyond for two samples in a row or -1, the largest fresh ratio).
    The supply is common to every valve: `legs_needed` legs beyond it mean the power unit, one
    leg alone its own transducer (or its P line). `latest[i]` keeps each leg's last sample."""
    count, lone, peak = 0, -1, 0.0
    for i in range(ps.shape[0]):
        if fresh[i]:
            latest[i] = ps[i]
            ratio[i] = abs(math.sqrt(max(ps[i] - tank_pa, 0.0) / drop_pa) - 1.0) / flow_spread
            run[i] = run[i] + 1 if ratio[i] > 1.0 else 0
            peak = max(peak, ratio[i])
        if ratio[i] > 1.0:
            count += 1
            if run[i] >= 2 and lone < 0:
                lone = i
    return count, (lone if count < legs_needed else -1), peak


class SupplyPressure:
    """The power unit's pressure as each valve's P-port transducer reads it (LEG_PRESSURE's PS,
    every 16th cycle per leg) against the supply the model assumes. `update` returns (supply
    faulty, the leg whose transducer alone disagrees or -1); `cycle_peak` is the largest ratio
    of the cycle's fresh samples; `latest_pa` each valve's last sample (the configured supply
    before any): the supply the chamber models run on."""

    def __init__(self, n_legs: int, nominal_pa: float, tank_pa: float, flow_spread: float, legs_needed: int):
        self.tank_pa, self.drop_pa, self.flow_spread = tank_pa, nominal_pa - tank_pa, flow_spread
        self.legs_needed = min(legs_needed, n_legs)
        self.latest_pa = np.full(n_legs, nominal_pa)
        self.ratio = np.zeros(n_legs)
        self.run = np.zeros(n_legs, dtype=np.int64)
        self.cycle_peak = 0.0

    def reset(self) -> None:
        self.ratio.fill(0.0)
        self.run.fill(0)

    def update(self, ps_pa: np.ndarray, fresh: np.ndarray) -> tuple[bool, int]:
        count, lone, self.cycle_peak = supply_step(ps_pa, fresh, self.tank_pa, self.drop_pa, self.flow_spread,
                                                   self.ratio, self.run, self.legs_needed, self.latest_pa)
        return count >= self.legs_needed, lone


@njit(cache=True)
def supply_at_rest_step(ps, fresh, nominal_pa, tolerance_pa, latest, seen, run, legs_needed):
    """Judge the valves' P-port samples while no leg draws flow: each leg's latest sample
    against the configured supply. Returns (legs whose latest sample is more than
    `tolerance_pa` off, the first leg off for two samples in a row or -1 when fewer than
    `legs_needed` are off, the mean of the latest samples (NaN before any), the largest
    |off| / tolerance)."""
    count, lone, total, heard, peak = 0, -1, 0.0, 0, 0.0
    for i in range(ps.shape[0]):
        if fresh[i]:
            latest[i] = ps[i]
            seen[i] = True
            run[i] = run[i] + 1 if abs(ps[i] - nominal_pa) > tolerance_pa else 0
        if not seen[i]:
            continue
        heard += 1
        total += latest[i]
        off = abs(latest[i] - nominal_pa) / tolerance_pa
        peak = max(peak, off)
        if off > 1.0:
            count += 1
            if run[i] >= 2 and lone < 0:
                lone = i
    return count, (lone if count < legs_needed else -1), (total / heard if heard else math.nan), peak


class SupplyAtRest:
    """The power unit's pressure while the platform holds (before a move, between moves): at
    rest the valves draw no flow and each P-port transducer reads the set pressure itself, so
    the supply the model assumes is checked directly, far tighter than the flow band a moving
    leg allows. `update` returns (supply off, the leg whose transducer alone disagrees or -1);
    `measured_pa` is the mean of the legs' latest samples (NaN while none is at rest). `moved()` when a move starts (its
    samples are not at rest, nor those while the accumulator refills after it)."""

    def __init__(self, n_legs: int, nominal_pa: float, tolerance_pa: float, legs_needed: int, settle_cycles: int = 0):
        self.nominal_pa, self.tolerance_pa = nominal_pa, tolerance_pa
        self.legs_needed = min(legs_needed, n_legs)
        self.settle_cycles, self.settling = settle_cycles, 0
        self.latest = np.zeros(n_legs)
        self.seen = np.zeros(n_legs, dtype=np.bool_)
        self.run = np.zeros(n_legs, dtype=np.int64)
        self.measured_pa = math.nan
        self.peak = 0.0

    def reset(self) -> None:
        self.seen.fill(False)
        self.run.fill(0)
        self.measured_pa = math.nan
        self.settling = 0

    def moved(self) -> None:
        """A move started: after it, the power unit refills what it drew for `settle_cycles`
        before the samples are at rest again."""
        self.reset()
        self.settling = self.settle_cycles

    def update(self, ps_pa: np.ndarray, fresh: np.ndarray) -> tuple[bool, int]:
        if self.settling > 0:
            self.settling -= 1
            return False, -1
        count, lone, self.measured_pa, self.peak = supply_at_rest_step(
            ps_pa, fresh, self.nominal_pa, self.tolerance_pa, self.latest, self.seen, self.run, self.legs_needed)
        return count >= self.legs_needed, lone
