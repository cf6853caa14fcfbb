"""The computed-torque controller's plant data: the valve map and the leg stiffness, derived
from the emulator's own equations (the way a rig's valve characteristic and oil-column
stiffness are measured once and loaded by its controller).

- valve map: the spool that holds a leg in the steady state at a hydraulic force F and a
  piston velocity v (no pressure change): `calibration.holding_point` with the velocity,
  over a grid. Steady pressures do not depend on the chamber volumes, so one map serves
  every stroke. Where no spool within full input reaches (F, v) (beyond the supply) the map
  holds the nearest reachable spool along F: the force loop and the saturation act there.
- stiffness: the median oil-column stiffness of the six legs over every waypoint of both
  movements (`hil.design.modes`), for the compliance flow F' / K of the feed-forward.
"""

from __future__ import annotations

import numpy as np

from physics.constants import MM
from plant_emulator.params import EmulatorConfig

from .calibration import holding_point

MAP_FORCES_N = np.arange(-250.0, 251.0, 20.0)
MAP_VELOCITIES_M_S = np.arange(-600.0, 601.0, 50.0) * MM
MAP_STROKE_M = 0.15                  # any: the steady state does not depend on it
# solver starts (PA, PB as fractions of the supply, spool): the steady state is unique where
# it exists, but from one start alone the solver misses it near the valve's null and the
# supply's reach
STARTS = ((0.5, 0.5, 0.0), (0.2, 0.6, -0.1), (0.04, 0.8, -0.3), (0.8, 0.04, 0.2), (0.08, 0.95, -0.5),
          (0.95, 0.08, 0.5))


def valve_map(cfg: EmulatorConfig, forces_n=MAP_FORCES_N, velocities_m_s=MAP_VELOCITIES_M_S
              ) -> tuple[np.ndarray, int]:
    """(n_forces, n_velocities) steady-state spool [fraction], and how many grid points no
    spool within full input reaches (filled along F)."""
    spool = np.full((len(forces_n), len(velocities_m_s)), np.nan)
    for j, v in enumerate(velocities_m_s):
        previous = None
        ps = cfg.supply_pressure_pa
        for i, force in enumerate(forces_n):
            for guess in (previous,) + tuple((a * ps, b * ps, x) for a, b, x in STARTS):
                if guess is None:
                    continue
                pa, pb, x, ok = holding_point(cfg, MAP_STROKE_M, float(force), velocity_m_s=float(v), guess=guess)
                if ok and abs(x) <= 1.0:
                    spool[i, j] = x
                    previous = (pa, pb, x)
                    break
    unreachable = int(np.isnan(spool).sum())
    for j in range(spool.shape[1]):
        column = spool[:, j]
        reached = ~np.isnan(column)
        if not reached.any():
            raise ValueError(f"valve map: no steady state at {velocities_m_s[j]:g} m/s")
        nearest = np.abs(np.arange(len(column))[:, None] - np.flatnonzero(reached)[None, :]).argmin(axis=1)
        spool[:, j] = column[np.flatnonzero(reached)[nearest]]
    return spool, unreachable


def leg_stiffness_n_m(cfg: EmulatorConfig) -> float:
    """The median oil-column stiffness of the legs at the waypoints of both movements."""
    from .modes import modal_model, movement_waypoints
    values = [modal_model(cfg, point).stiffness_n_m for points in movement_waypoints().values()
              for point in points]
    return float(np.median(np.concatenate(values)))


def _row(values, fmt: str = "{:.4g}") -> str:
    return "[" + ", ".join(fmt.format(v) for v in values) + "]"


def computed_torque_toml(spool: np.ndarray, stiffness_n_m: float, gains: dict, source: str) -> str:
    """A controller config file: the [computed_torque] gains and the [valve_map] (thesis units)."""
    lines = [f"# computed-torque plant data from {source} (`hydrapod design computed-torque`)",
             "[computed_torque]"]
    lines += [f"{key} = {value:g}" for key, value in gains.items()]
    lines.append(f"stiffness_n_mm = {stiffness_n_m * MM:.4g}")
    lines += ["", "[valve_map]",
              f"force_n = {_row(MAP_FORCES_N, '{:g}')}",
              f"velocity_mm_s = {_row(MAP_VELOCITIES_M_S / MM, '{:g}')}",
              "spool_pct = ["]
    lines += [f"    {_row(row * 100.0, '{:.4f}')}," for row in spool]
    lines.append("]")
    return "\n".join(lines) + "\n"
