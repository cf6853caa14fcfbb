"""The modal kick test's parts: the emulator's push on the platform (EMU_KICK) and the fit of
a free response (`hil.metrics.damped_oscillation`) on synthetic responses of known modes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.metrics import damped_oscillation
from plant_emulator.params import load_config
from plant_emulator.rigs import HexapodRig
from protocol.enums import KickAxis

PERIOD_S = 0.002


def free_response(t, modes, drift=(0.0, 0.0)):
    y = drift[0] + drift[1] * t
    for amplitude, zeta, frequency, phase in modes:
        w = 2 * math.pi * frequency
        y = y + amplitude * np.exp(-zeta * w * t) * np.sin(w * math.sqrt(1 - zeta ** 2) * t + phase)
    return y


@pytest.mark.parametrize("frequency, zeta", [(3.5, 0.15), (4.3, 0.05), (6.0, 0.3)])
def test_one_mode_on_a_drift_is_recovered(frequency, zeta):
    t = np.arange(0, 1.4, PERIOD_S)
    y = free_response(t, [(3e-4, zeta, frequency, 0.7)], drift=(0.58, -1e-4))
    y = np.round(y / 25e-6) * 25e-6                     # EMU_TRUTH's 0.025 mm steps
    fit = damped_oscillation(t, y)
    [mode] = fit["modes"]
    assert mode["frequency_hz"] == pytest.approx(frequency, rel=0.02)
    assert mode["damping_ratio"] == pytest.approx(zeta, rel=0.08)
    assert fit["r2"] > 0.97


def test_two_modes_are_recovered_largest_first():
    t = np.arange(0, 1.4, PERIOD_S)
    y = free_response(t, [(2e-4, 0.12, 4.3, 0.3), (1e-4, 0.17, 6.5, 1.9)])
    fit = damped_oscillation(t, y, count=2)
    first, second = fit["modes"]
    assert first["frequency_hz"] == pytest.approx(4.3, rel=0.01)
    assert second["frequency_hz"] == pytest.approx(6.5, rel=0.01)
    assert first["damping_ratio"] == pytest.approx(0.12, rel=0.03)
    assert fit["r2"] > 0.999


def test_noise_alone_gives_a_poor_fit():
    t = np.arange(0, 1.4, PERIOD_S)
    fit = damped_oscillation(t, np.random.default_rng(5).normal(0.0, 1e-4, len(t)))
    assert fit["r2"] < 0.5


def test_a_kick_pushes_the_platform_along_its_axis_for_its_duration():
    """A 20 N, 20 ms push along +y with the legs sealed: the platform moves +y, then swings
    back by more than half of it (the sealed chambers' spring; the seals' friction keeps part
    of the push); the push is gone after its duration (the applied wrench cleared)."""
    rig = HexapodRig(load_config())
    rig.ports_open[:] = 0.0
    for _ in range(50):
        rig.advance(PERIOD_S)
    y0 = rig.platform_pose()[0][1]
    rig.kick(int(KickAxis.Y), 20.0, 0.02)
    body = rig.mechanism.platform_body
    trace = []
    for k in range(150):
        rig.advance(PERIOD_S)
        trace.append(rig.platform_pose()[0][1] - y0)
        if k == 5:
            assert rig.mechanism.data.xfrc_applied[body, 1] == pytest.approx(20.0)
    assert not rig.mechanism.data.xfrc_applied[body].any()
    trace = np.array(trace)
    peak = int(np.argmax(trace))
    assert trace[peak] > 1e-4 and trace[peak:].min() < 0.5 * trace[peak]


def test_a_creep_beside_the_mode_fits_as_an_over_damped_component():
    """After a sealing that moved the platform, it creeps on while it rings: the two-mode fit
    gives the creep damping ratio ~1 (hex-kick takes the largest mode below 0.9)."""
    t = np.arange(0, 1.4, PERIOD_S)
    y = 4e-4 * np.exp(-t / 0.3) + free_response(t, [(2e-4, 0.15, 4.5, 0.4)])
    fit = damped_oscillation(t, y, count=2)
    creep = [m for m in fit["modes"] if m["damping_ratio"] >= 0.9]
    ring = [m for m in fit["modes"] if m["damping_ratio"] < 0.9]
    assert len(creep) == 1 and len(ring) == 1
    assert ring[0]["frequency_hz"] == pytest.approx(4.5, rel=0.02)
    assert ring[0]["damping_ratio"] == pytest.approx(0.15, rel=0.1)
