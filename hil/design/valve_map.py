"""The computed-torque controller's plant data: the valve map and the leg stiffness, derived
from the emulator's own equations (the way a rig's valve characteristic and oil-column
stiffness are measured once and loaded by its controller).

- valve map: the spool that holds a leg in the steady state at a hydraulic force F and a
  piston velocity v (no pressure change), and the chamber pressures there:
  `hydraulics.steady_state` with the velocity, over a grid. Steady pressures do not depend
  on the chamber volumes, so one map serves every stroke (the controller takes each leg's
  oil-column stiffness from these pressures and its stroke). Where no spool within full
  input reaches (F, v) (beyond the supply) the map holds the nearest reachable point along
  F: the force loop and the saturation act there.
"""

from __future__ import annotations

import numpy as np

from firmware_py.supervision.capacity import VELOCITY_GRID_M_S
from physics import hydraulics as hy
from physics.constants import BAR, MM
from plant_emulator.params import EmulatorConfig

# 4 N apart near the valve's null, where the steady pressures (the oil's stiffness) change
# fastest with the force (12 -> 55 N/mm between 0 and -8 N); 20 N apart beyond
MAP_FORCES_N = np.concatenate([np.arange(-250.0, -49.0, 20.0), np.arange(-40.0, 41.0, 4.0),
                               np.arange(50.0, 251.0, 20.0)])
# 2.5 mm/s apart near rest, where retracting pressurises the chambers (the flow gain changes
# 3x between 0 and -15 mm/s); 10 mm/s, then 50 mm/s apart to 600, then wider out to the
# capacity's reach: the map held at a nearer edge would cap the velocity loop's authority (a
# leg 20 mm behind at 0.5 m/s asked for no more spool)
_FAST_MM_S = np.append([700.0, 800.0, 1000.0, 1250.0, 1500.0, 2000.0, 2500.0], VELOCITY_GRID_M_S[-1] / MM)
MAP_VELOCITIES_M_S = np.concatenate([-_FAST_MM_S[::-1], np.arange(-600.0, -99.0, 50.0),
                                     np.arange(-80.0, -19.0, 10.0), np.arange(-15.0, 15.1, 2.5),
                                     np.arange(20.0, 81.0, 10.0), np.arange(100.0, 601.0, 50.0), _FAST_MM_S]) * MM
MAP_STROKE_M = 0.15                  # any: the steady state does not depend on it
# solver starts (PA, PB as fractions of the supply, spool): the steady state is unique where
# it exists, but from one start alone the solver misses it near the valve's null and the
# supply's reach
STARTS = ((0.5, 0.5, 0.0), (0.2, 0.6, -0.1), (0.04, 0.8, -0.3), (0.8, 0.04, 0.2), (0.08, 0.95, -0.5),
          (0.95, 0.08, 0.5))


def valve_map(cfg: EmulatorConfig, forces_n=MAP_FORCES_N, velocities_m_s=MAP_VELOCITIES_M_S
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(n_forces, n_velocities) steady-state spool [fraction] and chamber pressures PA, PB
    [Pa], and how many grid points no spool within full input reaches with both chambers
    between the cavitation floor and the supply (filled along F)."""
    shape = (len(forces_n), len(velocities_m_s))
    spool, pa_map, pb_map = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    ps, low = cfg.actuator.supply_pressure_pa, cfg.hp[hy.HP_P_MIN]    # a chamber below the floor cavitates
    for j, v in enumerate(velocities_m_s):
        previous = None
        for i, force in enumerate(forces_n):
            for guess in (previous,) + tuple((a * ps, b * ps, x) for a, b, x in STARTS):
                if guess is None:
                    continue
                pa, pb, x, ok = hy.steady_state(MAP_STROKE_M, float(force), ps, cfg.hp, velocity_m_s=float(v),
                                                guess=guess)
                if ok and abs(x) <= 1.0 and low <= min(pa, pb) and max(pa, pb) <= ps:
                    spool[i, j], pa_map[i, j], pb_map[i, j] = x, pa, pb
                    previous = (pa, pb, x)
                    break
    unreachable = int(np.isnan(spool).sum())
    for j in range(shape[1]):
        reached = np.flatnonzero(~np.isnan(spool[:, j]))
        if not len(reached):
            raise ValueError(f"valve map: no steady state at {velocities_m_s[j]:g} m/s")
        nearest = reached[np.abs(np.arange(shape[0])[:, None] - reached[None, :]).argmin(axis=1)]
        for table in (spool, pa_map, pb_map):
            table[:, j] = table[nearest, j]
    return spool, pa_map, pb_map, unreachable


def _row(values, fmt: str = "{:.4g}") -> str:
    return "[" + ", ".join(fmt.format(v) for v in values) + "]"


def computed_torque_toml(spool: np.ndarray, pressure_a_pa: np.ndarray, pressure_b_pa: np.ndarray, gains: dict,
                         source: str, supply_pa: float) -> str:
    """A controller config file: the [computed_torque] gains and the [valve_map] (thesis units)."""
    lines = [f"# computed-torque plant data from {source} (`hydrapod design computed-torque`)",
             "[computed_torque]"]
    lines += [f"{key} = {value:g}" for key, value in gains.items()]
    lines += ["", "[valve_map]", f"supply_pressure_bar = {supply_pa / BAR:g}",
              f"force_n = {_row(MAP_FORCES_N, '{:g}')}",
              f"velocity_mm_s = {_row(MAP_VELOCITIES_M_S / MM, '{:g}')}"]
    for name, table, scale in (("spool_pct", spool, 100.0), ("pressure_a_bar", pressure_a_pa, 1.0 / BAR),
                               ("pressure_b_bar", pressure_b_pa, 1.0 / BAR)):
        lines.append(f"{name} = [")
        lines += [f"    {_row(row * scale, '{:.4f}')}," for row in table]
        lines.append("]")
    return "\n".join(lines) + "\n"


def force_rate_floor(cfg: EmulatorConfig, spool: np.ndarray, pressure_a: np.ndarray, pressure_b: np.ndarray,
                     models) -> float:
    """The smallest force rate per spool, N/s (`hydraulics.force_rate_per_spool` at the map's
    steady state of each leg's static force at rest), over the design's operating set:
    where the controller meets a lower one it takes this (its force loop's gain goes no
    higher than the closed-loop design checked)."""
    from firmware_py.motion_control.computed_torque import valve_map_eval
    floor = np.inf
    for _, model in models:
        for i, force in enumerate(model.static_force_n):
            args = (MAP_FORCES_N, MAP_VELOCITIES_M_S)
            pa, pb = valve_map_eval(*args, pressure_a, float(force), 0.0), valve_map_eval(*args, pressure_b,
                                                                                          float(force), 0.0)
            x = valve_map_eval(*args, spool, float(force), 0.0)
            rate = hy.force_rate_per_spool(float(model.strokes_m[i]), pa, pb, x, cfg.actuator.supply_pressure_pa,
                                           cfg.hp)
            floor = min(floor, rate)
    return float(floor)
