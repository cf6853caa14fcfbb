"""Stick-slip (thesis 6.2): the limit cycle a slow constant-velocity drive under PI falls
into, predicted by the LuGre model on the linearised actuator.

The model: the emulator's actuator linearised where it slides at the drive's speed (its
chambers holding the weight plus the seals' and guide's steady friction there, eq. 6.4;
`hil.design.calibration.state_space`), the seals' and the guide's LuGre friction (eq.
6.1-6.3, `physics.lugre`) as its load, the controller's own PI law (`pi_antiwindup`) on the
encoder's counts, one period of command latency (VALVE_CMD k acts from SYNC k+1), sub-steps
as the emulator takes them. The friction is nonlinear, the hydraulics linear: where they
agree with the HIL run, the limit cycle is the friction's.

`limit_cycle` measures a tracking error's cycle the same way for the model and the HIL log.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.linalg import expm

from firmware_py.config import ControllerConfig
from firmware_py.motion_control.joint_space import pi_antiwindup
from hil.design.calibration import state_space
from physics import lugre
from physics.constants import MM
from plant_emulator.params import EmulatorConfig

PERIOD_S = 0.002
SETTLE_S = 1.0                     # the ramp's start left out of the measurement
CYCLING_MIN_M = 0.1 * MM           # a limit cycle: the error's 5-95 % spread at least this
PAD = 8                            # zero padding of the error's spectrum (its peak, finer)


def limit_cycle(error_m: np.ndarray, period_s: float = PERIOD_S) -> dict:
    """The detrended error's spread (5-95 %, m), its dominant period (s) and whether it
    cycles; NaN samples left out."""
    e = np.asarray(error_m, float)
    e = e[np.isfinite(e)]
    if len(e) < 8:
        return {"spread_m": math.nan, "period_s": None, "cycling": False}
    e = e - np.polyval(np.polyfit(np.arange(len(e)), e, 1), np.arange(len(e)))      # a drift is no cycle
    spread = float(np.percentile(e, 95) - np.percentile(e, 5))
    spectrum = np.abs(np.fft.rfft(e * np.hanning(len(e)), PAD * len(e)))
    f = np.fft.rfftfreq(PAD * len(e), period_s)
    peak = int(np.argmax(spectrum[1:])) + 1
    return {"spread_m": spread, "period_s": float(1.0 / f[peak]), "cycling": spread >= CYCLING_MIN_M}


@njit(cache=True)
def _ramp(ad, bd, fp, gp, damping, offset_n, kp, ki, u_max, count_m, velocity, n, substeps, period_s, error, speed):
    """n periods of the ramp y_r = velocity t from rest; error[k] = y_r - y, speed[k] = v."""
    h = period_s / substeps
    x = np.zeros(ad.shape[0])
    inputs = np.zeros(2)
    integral = np.zeros(1)
    z_seal = 0.0
    z_guide = 0.0
    u_next = 0.0
    for k in range(n):
        y_r = velocity * k * period_s
        measured = math.floor(x[0] / count_m + 0.5) * count_m
        inputs[0] = u_next                                          # last period's command
        u_next = pi_antiwindup(y_r - measured, integral, 0, kp, ki, 0.0, period_s, u_max)
        for _ in range(substeps):
            v = x[1]
            seal_z, seal_c = lugre.force_split(z_seal, v, fp)
            guide_z, guide_c = lugre.force_split(z_guide, v, gp)
            # the linearisation already holds offset_n and the viscous slope: the rest is load
            inputs[1] = seal_z + seal_c * v + guide_z + guide_c * v - damping * v - offset_n
            x = ad @ x + bd @ inputs
            z_seal = lugre.z_step(z_seal, v, h, fp)
            z_guide = lugre.z_step(z_guide, v, h, gp)
        error[k] = velocity * (k + 1) * period_s - x[0]
        speed[k] = x[1]


def predict(emulator: EmulatorConfig, controller: ControllerConfig, velocity_m_s: float, load_kg: float,
            position_m: float, seconds: float, period_s: float = PERIOD_S) -> dict:
    """The model's ramp at `velocity_m_s` (upward) for `seconds` around `position_m`: its
    limit cycle (`limit_cycle`, after SETTLE_S) and the record (t, error, velocity)."""
    fp, gp = emulator.friction.vector, emulator.guide.lugre_vector(load_kg)
    sliding_n = lugre.steady_friction(velocity_m_s, fp) + lugre.steady_friction(velocity_m_s, gp)
    space = state_space(emulator, position_m / MM, load_kg, sliding_n)
    a = np.zeros((5, 5))                                # [y, v, PA, PB, spool]
    a[0, 1] = 1.0
    a[1:, 1:] = space.a
    b = np.zeros((5, 2))
    b[1:, 0], b[1:, 1] = space.b, space.f
    augmented = np.zeros((7, 7))
    augmented[:5, :5], augmented[:5, 5:] = a, b
    substeps = max(int(round(period_s / emulator.testbench.substep_s)), 1)
    phi = expm(augmented * period_s / substeps)
    n = int(round(seconds / period_s))
    error, speed = np.zeros(n), np.zeros(n)
    pi = controller.pi
    _ramp(np.ascontiguousarray(phi[:5, :5]), np.ascontiguousarray(phi[:5, 5:]), fp, gp, space.damping_ns_m,
          sliding_n, pi.kp_v_m, pi.ki_v_m_s, pi.saturation_v * controller.limits.spool_max,
          emulator.sensors.encoder_resolution_m, velocity_m_s, n, substeps, period_s, error, speed)
    skip = int(round(SETTLE_S / period_s))
    return {**limit_cycle(error[skip:], period_s), "t_s": np.arange(n) * period_s, "error_m": error,
            "velocity_m_s": speed}
