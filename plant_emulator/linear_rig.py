"""The thesis's identified actuator (Table A.3) as a rig: the one linear plant of the linear
studies. Per leg P(s) = Y/Xv = k01 b0 / (s (s^2 + b1 s + b0)) (eq. 5.2), Xv the valve input
in volts, stepped exactly over each period with the input held (zero-order hold); the load
cell reads the moving mass's m (y'' + g); the spool a first-order lag of the command (what
its transducer reports); no chambers, so no pressure transducers.

It has the surface of the rigs in `rigs.py`, so `SimulatedRig` puts it behind the same
valves and sensors (a controller sees it through the same Measurements).
"""

from __future__ import annotations

import math
import tomllib
from functools import cache
from importlib import resources

import numpy as np

from physics import hydraulics as hy
from physics.constants import GRAVITY_M_S2, MM

TABLE_A3_LOADS_KG = (0.0, 3.0, 6.0)


@cache
def table_a3() -> np.ndarray:
    """Rows [Po_mm, b0_0k, b1_0k, k01_0k, b0_3k, b1_3k, k01_3k, b0_6k, b1_6k, k01_6k] (thesis units)."""
    with resources.files("plant_emulator").joinpath("data/table_A3.toml").open("rb") as handle:
        return np.asarray(tomllib.load(handle)["rows"], dtype=float)


def identified_plant(position_mm: float, load_kg: float) -> tuple[float, float, float]:
    """Table A.3's (b0 [1/s^2], b1 [1/s], k01 [(m/s)/V]) at one of its set points."""
    rows = table_a3()
    row = rows[np.flatnonzero(rows[:, 0] == position_mm)]
    if len(row) != 1 or load_kg not in TABLE_A3_LOADS_KG:
        raise ValueError(f"Table A.3 has no plant at {position_mm} mm, {load_kg} kg")
    j = TABLE_A3_LOADS_KG.index(load_kg)
    b0, b1, k01 = row[0, 1 + 3 * j:4 + 3 * j]
    return float(b0), float(b1), float(k01) * MM


class LinearRig:
    """`n_legs` independent identified actuators, starting at rest at `strokes_m`."""

    name = "linear"
    has_pressure_transducers = False

    def __init__(self, n_legs: int, b0: float, b1: float, k01_m_s_v: float, strokes_m, load_mass_kg: float,
                 full_scale_v: float, spool_time_constant_s: float, stroke_m: float, supply_pa: float):
        self.n_legs = n_legs
        self.b0, self.b1, self.k01 = b0, b1, k01_m_s_v
        self._k01_nominal = k01_m_s_v
        self.load_mass_kg, self.full_scale_v = load_mass_kg, full_scale_v
        self.spool_tau_s, self.stroke_limit_m = spool_time_constant_s, stroke_m
        self.state = np.zeros((n_legs, hy.S_SIZE))
        self.state[:, hy.S_Y] = strokes_m
        self._acceleration = np.zeros(n_legs)
        self.command = np.zeros(n_legs)
        self.jammed = np.zeros(n_legs, dtype=bool)
        self.seized = np.zeros(n_legs, dtype=bool)
        self.ports_open = np.ones(n_legs)
        self.seal_leak = np.zeros(n_legs)
        self.rod_force_n = np.full(n_legs, load_mass_kg * GRAVITY_M_S2)
        self.supply_pressure_pa = supply_pa
        self.time_s = 0.0
        self.unstable_periods = 0
        self.joint_limit_periods = 0
        self.first_joint_limit_s = None
        self.first_unstable_s = None
        self._steps: dict[float, tuple[np.ndarray, np.ndarray, float]] = {}

    @classmethod
    def table_a3(cls, cfg, position_mm: float, load_kg: float, n_legs: int = 1, slide_mass_kg: float = 1.35):
        """Table A.3's plant at a set point, with the emulator's valve (its full scale and spool
        lag), the cylinder's stroke and the supply; the load cell carries the slide and the load."""
        b0, b1, k01 = identified_plant(position_mm, load_kg)
        return cls(n_legs, b0, b1, k01, np.full(n_legs, position_mm * MM), slide_mass_kg + load_kg,
                   cfg.actuator.valve_full_scale_v, float(cfg.hp[hy.HP_TAU_SPOOL]), cfg.stroke_m,
                   cfg.actuator.supply_pressure_pa)

    def _step(self, period_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(Ad, Bd, spool decay) of one period: exact under a held input."""
        if period_s not in self._steps:
            from scipy.linalg import expm
            a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -self.b0, -self.b1]])
            b = np.array([0.0, 0.0, self.k01 * self.b0])
            augmented = np.zeros((4, 4))
            augmented[:3, :3], augmented[:3, 3] = a, b
            phi = expm(augmented * period_s)
            self._steps[period_s] = (phi[:3, :3], phi[:3, 3], math.exp(-period_s / self.spool_tau_s))
        return self._steps[period_s]

    def advance(self, period_s: float) -> None:
        ad, bd, decay = self._step(period_s)
        st = self.state
        for i in range(self.n_legs):
            target = min(max(float(self.command[i]), -1.0), 1.0)
            if not self.jammed[i]:
                st[i, hy.S_SPOOL] = target + (st[i, hy.S_SPOOL] - target) * decay
            x = np.array([st[i, hy.S_Y], st[i, hy.S_V], self._acceleration[i]])
            if self.seized[i]:
                x[1:] = 0.0
            else:
                x = ad @ x + bd * (target * self.full_scale_v)
            if not 0.0 <= x[0] <= self.stroke_limit_m:                 # end stops: inelastic
                x[0], x[1], x[2] = min(max(x[0], 0.0), self.stroke_limit_m), 0.0, 0.0
            st[i, hy.S_Y], st[i, hy.S_V], self._acceleration[i] = x
            self.rod_force_n[i] = self.load_mass_kg * (x[2] + GRAVITY_M_S2)
        self.time_s += period_s

    @property
    def stroke_m(self) -> np.ndarray:
        return self.state[:, hy.S_Y]

    def warm_up(self) -> None:
        """No compiled kernels."""

    def set_load(self, load_kg: float) -> None:
        """The identified plant is one load's; only the load cell's mass follows."""
        self.load_mass_kg = float(load_kg)

    def set_rod_seized(self, leg: int, seized: bool) -> None:
        self.seized[leg] = seized

    def set_seal_leak(self, leg: int, factor: float) -> None:
        """No chambers: a seal cannot leak here."""

    def set_supply_fraction(self, fraction: float) -> None:
        """The flow gain k01 goes with the square root of the supply's pressure drop."""
        self.k01 = self._k01_nominal * math.sqrt(min(max(fraction, 0.0), 1.0))
        self._steps.clear()
