"""What the legs can give against what a movement asks: each leg's force capacity at its
velocity (`physics.hydraulics.capacity_table`: the valve fully open, the chambers in steady
state, the seals' steady friction taken off) against eq. 10.5's actuator forces along the
movement's reference, with the payload. The utilisation is the largest ratio of the force a
leg needs to the force it can give at that velocity over the movement and the legs; above 1
the movement asks more than the actuators give, and the smallest time scale at which it is
1 is what that movement needs. Uses the controller's own models (its `[hydraulic_model]`,
`[friction]`, geometry and payload), as a check at commit would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.platform import PlatformModel
from hil.experiments import MOTIONS, Motion
from physics import hydraulics as hy
from physics import lugre

PERIOD_S = 0.002
VELOCITY_GRID_M_S = np.linspace(-3.0, 3.0, 241)     # 25 mm/s apart; the valve's no-load speed is ~3.4 m/s
SCALE_RANGE = (0.25, 8.0)                          # the time scales the search spans


@dataclass
class LegCapacity:
    """One leg's force range [N] over the velocity grid, net of the seals' steady friction."""
    velocities_m_s: np.ndarray
    push_n: np.ndarray               # the largest force toward extension (NaN: beyond the valve's speed)
    pull_n: np.ndarray               # the smallest (most negative)

    @classmethod
    def of(cls, cfg: ControllerConfig, supply_pa: float | None = None) -> LegCapacity:
        ps = cfg.hydraulic_model.supply_pressure_pa if supply_pa is None else supply_pa
        table = hy.capacity_table(VELOCITY_GRID_M_S, ps, cfg.hydraulics)
        friction = np.array([lugre.steady_friction(float(v), cfg.friction.vector) for v in VELOCITY_GRID_M_S])
        return cls(VELOCITY_GRID_M_S, table[:, 0] - friction, table[:, 1] - friction)

    def utilisation(self, force_n: np.ndarray, velocity_m_s: np.ndarray) -> np.ndarray:
        """Each force's ratio to what the leg gives at its velocity in its direction (inf
        where it cannot: beyond the valve's speed, or a side that no longer reaches zero)."""
        push = np.interp(velocity_m_s, self.velocities_m_s, self.push_n)
        pull = np.interp(velocity_m_s, self.velocities_m_s, self.pull_n)
        pushing = force_n >= 0.0
        limit = np.where(pushing, push, pull)
        reaches = np.isfinite(limit) & np.where(pushing, limit > 0.0, limit < 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(reaches, force_n / limit, np.inf)


@dataclass
class Utilisation:
    movement: str
    payload_kg: float
    supply_bar: float
    time_scale: float
    utilisation: float               # the largest ratio over the movement and the legs
    at_s: float                      # where (time into the movement) ...
    leg: int                         # ... and which leg (1..6)
    force_n: float                   # the force it needs there
    velocity_m_s: float              # at that velocity
    needed_scale: float              # the time scale at which the utilisation is 1 (NaN: beyond the search)

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in self.__dict__.items()}


def movement(name: str, time_scale: float) -> Motion:
    """The thesis's movement (without the approach from home) at `time_scale` x its ta, tm."""
    motion = MOTIONS[name](default_geometry())
    return replace(motion, parts=motion.parts[1:], ta_s=motion.ta_s * time_scale, tm_s=motion.tm_s * time_scale)


def _peak(cfg: ControllerConfig, capacity: LegCapacity, name: str, payload_kg: float, time_scale: float):
    """(utilisation, t, leg index, force, velocity) at the worst sample of the movement."""
    geometry = default_geometry().with_payload(payload_kg)
    motion = movement(name, time_scale)
    trajectory = motion.joint_trajectory(geometry)
    platform = PlatformModel(geometry, cfg.kinematics.dk_tolerance_m, cfg.kinematics.dk_max_iterations, PERIOD_S)
    lengths, rates, accel = (np.empty(6) for _ in range(3))
    times = np.arange(0.0, trajectory.duration_s, PERIOD_S)
    forces, velocities = np.empty((len(times), 6)), np.empty((len(times), 6))
    for k, t in enumerate(times):
        trajectory.evaluate_into(float(t), lengths, rates, accel)
        strokes = lengths - geometry.leg_min_m
        if k == 0:
            platform.reset_reference(strokes)
        platform.reference_forces(strokes, rates)
        forces[k], velocities[k] = platform.force_n, rates
    forces[0] = forces[1]                            # the first sample's acceleration has no cycle before
    ratio = capacity.utilisation(forces, velocities)
    k, leg = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return float(ratio[k, leg]), float(times[k]), int(leg), float(forces[k, leg]), float(velocities[k, leg])


def utilisation(cfg: ControllerConfig, name: str, payload_kg: float = 0.0, supply_bar: float | None = None,
                time_scale: float = 1.0, needed: bool = True) -> Utilisation:
    """The movement's utilisation at `time_scale`, and (`needed`) the time scale at which it is 1."""
    supply_pa = cfg.hydraulic_model.supply_pressure_pa if supply_bar is None else supply_bar * 1e5
    capacity = LegCapacity.of(cfg, supply_pa)
    peak, at_s, leg, force, velocity = _peak(cfg, capacity, name, payload_kg, time_scale)
    return Utilisation(name, payload_kg, supply_pa / 1e5, time_scale, peak, at_s, leg + 1, force, velocity,
                       needed_scale(cfg, capacity, name, payload_kg) if needed else math.nan)


def needed_scale(cfg: ControllerConfig, capacity: LegCapacity, name: str, payload_kg: float,
                 tolerance: float = 0.01) -> float:
    """The smallest time scale (within SCALE_RANGE, to `tolerance`) at which the movement's
    utilisation is at most 1; NaN when even the slowest asks too much (a static load beyond
    the legs) or the fastest is within capacity."""
    low, high = SCALE_RANGE
    if _peak(cfg, capacity, name, payload_kg, high)[0] > 1.0 or _peak(cfg, capacity, name, payload_kg, low)[0] <= 1.0:
        return math.nan
    while high - low > tolerance:
        middle = 0.5 * (low + high)
        if _peak(cfg, capacity, name, payload_kg, middle)[0] <= 1.0:
            high = middle
        else:
            low = middle
    return round(high, 3)


def format_utilisation(rows: list[Utilisation]) -> str:
    lines = ["movement  payload kg  supply bar  time scale  utilisation  where (leg, t s, F N, v mm/s)      "
             "needs time scale"]
    for r in rows:
        needs = "-" if math.isnan(r.needed_scale) else f"{r.needed_scale:.2f}"
        lines.append(f"{r.movement:<9} {r.payload_kg:>10.1f} {r.supply_bar:>11.1f} {r.time_scale:>11.2f} "
                     f"{r.utilisation:>12.2f}  leg {r.leg}, {r.at_s:5.2f} s, {r.force_n:7.1f} N, "
                     f"{r.velocity_m_s * 1e3:7.1f}  {needs:>16}")
    return "\n".join(lines)
