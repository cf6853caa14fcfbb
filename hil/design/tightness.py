"""`hydrapod design tightness`: is the capacity check tight, not padded? At each point of the
envelope (a thesis movement, payload and supply declared), in process, emulator truth:

- the plan's time scale P (`capacity.plan`: what the controller accepts);
- P / TIGHT_FACTOR (15 % faster): does the controller refuse it, and, run with the check
  opened, how long does a valve sit at its limit;
- the fastest time scale at which the movement still completes within ERROR_BOUND_MM, the
  check opened: swept from P down (or up, where P itself misses) in STEP steps, and the
  waypoint the controller refuses there (what pads the plan). A run's time scale is the one it
  ran at: the one sent times its stretch, where the online time scaling slowed its clock (a
  run sent faster than the legs give is slowed to what they give, not run at what was sent).

Tight: P/TIGHT_FACTOR is refused or saturates, the run at P completes within the bound, and
P is within TIGHT_FACTOR of the fastest that completes, either way. P below the fastest is the
check's optimism (the run at P completes only because its clock slows: `planned_stretch`); P
more than TIGHT_FACTOR above, its padding. "The check opened":
the controller's own waypoint check with legs of unbounded force and an ideal supply (the
workspace, singularity and speed checks stay); the online time scaling stays on.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

TIGHT_FACTOR = 1.15
ERROR_BOUND_MM = 10.0
STEP = 0.05                          # the sweep's step, a fraction of P
SWEEP_RANGE = (0.4, 2.0)             # x P: where the sweep gives up
SATURATED = 0.999                    # |valve command| at or above this share of its limit


@dataclass
class Tightness:
    movement: str
    payload_kg: float
    supply_bar: float
    planned_scale: float             # NaN: no timing fits
    faster_refused: bool             # the controller refuses P / TIGHT_FACTOR
    faster_saturated_ms: float       # ... run anyway: how long a valve sat at its limit
    faster_error_mm: float           # ... and its largest error
    planned_error_mm: float          # the run at P, the check opened (as accepted)
    fastest_scale: float             # the fastest that completes within the bound, as run (NaN: none in range)
    fastest_error_mm: float
    refused_at: str = ""             # the waypoint the controller refuses at the fastest ("": accepts it)
    fastest_sent: float = math.nan   # ... the time scale sent for it (its clock slowed: less than as run)
    planned_stretch: float = 1.0     # how much longer than its timing the run at P took
    planned_completes: bool = True   # the run at P completes within ERROR_BOUND_MM

    @property
    def ratio(self) -> float:
        """P over the fastest that completes: < 1 the check is optimistic, > TIGHT_FACTOR padded."""
        return self.planned_scale / self.fastest_scale

    @property
    def tight(self) -> bool:
        exceeds = self.faster_refused or self.faster_saturated_ms > 0.0
        return exceeds and self.planned_completes and 1.0 / TIGHT_FACTOR <= self.ratio <= TIGHT_FACTOR

    def as_dict(self) -> dict:
        out = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in self.__dict__.items()}
        ratio = self.ratio
        return out | {"ratio": ratio if math.isfinite(ratio) else None, "tight": self.tight}


def open_check(loop) -> None:
    """The controller's waypoint check with legs of unbounded force and an ideal supply (the
    workspace, singularity and speed checks stay)."""
    from firmware_py.supervision.capacity import VELOCITY_GRID_M_S, LegCapacity
    unbounded = np.full(VELOCITY_GRID_M_S.shape, 1e9)
    loop.ctl.rig.check.capacity = LegCapacity(VELOCITY_GRID_M_S, unbounded, -unbounded)


def opened_run(controller_cfg, emulator_cfg, motion, payload_kg: float, scale: float, seed: int = 7):
    """The movement at `scale` through the controller with its capacity check opened
    (`simulate.Movement`)."""
    from hil.design.simulate import movement
    from hil.in_process import InProcessLoop
    loop = InProcessLoop(controller_cfg, emulator_cfg, "computed-torque", payload_kg, seed)
    open_check(loop)
    loop.activate()
    return movement(loop, motion.scaled(scale))


def _passes(run) -> bool:
    return run.completed and float(np.max(run.max_error_m)) * 1e3 <= ERROR_BOUND_MM


def tightness(movement: str, payload_kg: float, supply_bar: float, seed: int = 7,
              config_path: str | None = None) -> Tightness:
    """One point; `config_path`: controller config sections over the packaged configuration."""
    from hil.design.capacity import PERIOD_S, commit_all, plan
    from hil.design.simulate import point_configs, thesis_motions
    from protocol.enums import Ack
    cfg, emulator = point_configs(payload_kg, supply_bar, config_path=config_path)
    motion = thesis_motions()[movement]
    planned = plan(cfg, motion).time_scale
    if not math.isfinite(planned):
        nan = math.nan
        return Tightness(movement, payload_kg, supply_bar, nan, True, nan, nan, nan, nan, nan)

    def run(scale):
        return opened_run(cfg, emulator, motion, payload_kg, scale, seed)

    def largest_mm(r) -> float:
        return float(np.max(r.max_error_m)) * 1e3

    faster = planned / TIGHT_FACTOR
    refused = commit_all(cfg, motion.scaled(faster))[0] is not Ack.ACCEPTED
    fast_run = run(faster)
    at_limit = np.any(np.abs(fast_run.spool) >= SATURATED * cfg.limits.spool_max, axis=1)
    saturated_ms = float(np.sum(at_limit)) * PERIOD_S * 1e3
    at_plan = run(planned)
    fastest, fastest_mm, sent = math.nan, math.nan, math.nan

    def take(r, scale) -> None:
        """Keep the run if it ran faster than the fastest so far (its timing as run)."""
        nonlocal fastest, fastest_mm, sent
        as_run = scale * r.stretch
        if math.isnan(fastest) or as_run < fastest:
            fastest, fastest_mm, sent = as_run, largest_mm(r), scale

    planned_completes = _passes(at_plan)
    if planned_completes:                              # down from P while it completes within the bound
        take(at_plan, planned)
        k = 1
        while planned * (1.0 - k * STEP) >= SWEEP_RANGE[0] * planned:
            scale = planned * (1.0 - k * STEP)
            r = run(scale)
            if not _passes(r):
                break
            take(r, scale)
            k += 1
    else:                                              # up from P to the first that completes
        k = 1
        while planned * (1.0 + k * STEP) <= SWEEP_RANGE[1] * planned:
            r = run(planned * (1.0 + k * STEP))
            if _passes(r):
                take(r, planned * (1.0 + k * STEP))
                break
            k += 1
    refused_at = ""
    if math.isfinite(sent):
        result, seq, position_m, _ = commit_all(cfg, motion.scaled(sent))
        if result is not Ack.ACCEPTED:
            refused_at = f"{seq + 1} ({', '.join(f'{v:.0f}' for v in position_m * 1e3)})"
    return Tightness(movement, payload_kg, supply_bar, planned, refused, saturated_ms, largest_mm(fast_run),
                     largest_mm(at_plan), fastest, fastest_mm, refused_at, sent, at_plan.stretch,
                     planned_completes)


def _job(args) -> Tightness:
    return tightness(*args)


def sweep_tightness(movements, payloads_kg, supplies_bar, seed: int = 7, workers: int = 2,
                    config_path: str | None = None) -> list[Tightness]:
    jobs = [(m, p, s, seed, config_path) for m in movements for p in payloads_kg for s in supplies_bar]
    if workers <= 1:
        return [_job(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_job, jobs))


def format_tightness(rows: list[Tightness]) -> str:
    lines = [f"movement  kg   bar  plan   x{TIGHT_FACTOR:.2f} faster: refused  saturated ms  error mm   "
             f"at plan mm (as run)  fastest <= {ERROR_BOUND_MM:g} mm as run (error; sent)  plan/fastest  tight  "
             f"refused there: waypoint (mm)"]
    for r in rows:
        if not math.isfinite(r.planned_scale):
            lines.append(f"{r.movement:<9} {r.payload_kg:<4g} {r.supply_bar:<4g} no timing fits")
            continue
        fastest = (f"{r.fastest_scale:.2f} ({r.fastest_error_mm:.1f}; sent {r.fastest_sent:.2f})"
                   if math.isfinite(r.fastest_scale) else "none")
        lines.append(f"{r.movement:<9} {r.payload_kg:<4g} {r.supply_bar:<4g} {r.planned_scale:4.2f}   "
                     f"{'yes' if r.faster_refused else 'no':>21}  {r.faster_saturated_ms:12.0f}  "
                     f"{r.faster_error_mm:8.1f}   {r.planned_error_mm:5.1f} (x{r.planned_stretch:.2f})  {fastest:>34}  "
                     f"{r.ratio:12.2f}  {'yes' if r.tight else 'no ':<5}  {r.refused_at or '-'}")
    tight = sum(r.tight for r in rows)
    lines.append(f"tight at {tight} of {len(rows)} points")
    return "\n".join(lines)
