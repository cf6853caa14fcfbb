"""`hydrapod design sweep`: one [computed_torque] key over a few values, the thesis's two
movements in process (`simulate.run_movement`) at points of the operating envelope and for
several sensor-noise seeds: each run's IAE against the thesis's model-based and its largest
error, emulator truth. How the gains the search does not derive were chosen (the twist's
low-pass, the stiff directions' integral); HIL runs stay the judge of record.

A movement runs at the thesis's timing where the planner (`capacity.plan`) fits it, else at
the plan's, as the envelope campaigns' `--time-scale fit` does; where none fits it is
reported refused. Each run
gets the payload and supply declared to the controller.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

# (payload kg, supply bar): the nominal point, and the envelope's corners and middle
POINTS = {"nominal": ((0.0, 25.0),),
          "envelope": ((0.0, 20.0), (0.0, 40.0), (1.5, 25.0), (3.0, 40.0), (4.5, 40.0), (6.0, 40.0))}
MOVEMENTS = ("circle", "diagonal")


@dataclass
class SweepRun:
    value: float
    payload_kg: float
    supply_bar: float
    movement: str
    seed: int
    time_scale: float
    fault: str
    iae_ratio: tuple[float, float, float]     # x, y, z against the thesis's model-based
    max_error_mm: tuple[float, float, float]

    def as_dict(self) -> dict:
        return {"value": self.value, "payload_kg": self.payload_kg, "supply_bar": self.supply_bar,
                "movement": self.movement, "seed": self.seed, "time_scale": self.time_scale, "fault": self.fault,
                "iae_ratio": [round(v, 3) for v in self.iae_ratio],
                "max_error_mm": [round(v, 2) for v in self.max_error_mm]}


def _run(args) -> SweepRun:
    key, value, payload, supply, movement, seed = args
    from hil.design.capacity import plan
    from hil.design.simulate import point_configs, run_movement, thesis_motions
    from hil.experiments import THESIS_MOVEMENTS
    cfg, emulator = point_configs(payload, supply, {key: value})
    motion = thesis_motions()[movement]
    scale = max(plan(cfg, motion).time_scale, 1.0)        # `--time-scale fit`
    if not math.isfinite(scale):                          # no timing holds it: refused, nothing runs
        return SweepRun(value, payload, supply, movement, seed, scale, "BEYOND_CAPACITY", (math.nan,) * 3,
                        (math.nan,) * 3)
    run = run_movement(cfg, emulator, motion, payload_kg=payload, seed=seed, time_scale=scale)
    thesis = THESIS_MOVEMENTS[movement]["iae_model_based"]
    iae = tuple(float(run.iae_m_s[i] / thesis[a]) for i, a in enumerate("xyz"))
    return SweepRun(value, payload, supply, movement, seed, scale, run.fault, iae,
                    tuple(float(v) for v in run.max_error_m * 1e3))


def sweep(key: str, values, points, movements=MOVEMENTS, seeds=(1, 2, 3), workers: int = 2) -> list[SweepRun]:
    """Every value x point x movement x seed (the configuration of each checked first, here)."""
    from firmware_py.config import load_config
    for value in values:                 # a value the config refuses: one line, before any run
        load_config(overrides={"computed_torque": {key: value}})
    jobs = [(key, float(value), payload, supply, movement, seed) for value in values for payload, supply in points
            for movement in movements for seed in seeds]
    if workers <= 1:
        return [_run(job) for job in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_run, jobs))


def format_sweep(key: str, runs: list[SweepRun]) -> str:
    """Per value, point and movement: the IAE ratios' mean and largest over the seeds, the
    largest error over them, the faults."""
    lines = [f"{key:>24} {'kg':>4} {'bar':>4} {'movement':<9} {'scale':>5}  IAE / thesis x y z: mean (max)"
             f"{'':>14} largest mm x y z   faults"]
    groups: dict[tuple, list[SweepRun]] = {}
    for r in runs:
        groups.setdefault((r.value, r.payload_kg, r.supply_bar, r.movement), []).append(r)
    for (value, payload, supply, movement), rs in groups.items():
        iae = np.array([r.iae_ratio for r in rs])
        largest = np.max([r.max_error_mm for r in rs], axis=0)
        faults = ",".join(sorted({r.fault for r in rs} - {"NONE"})) or "-"
        cells = " ".join(f"{m:.2f} ({x:.2f})" for m, x in zip(iae.mean(axis=0), iae.max(axis=0)))
        lines.append(f"{value:>24g} {payload:>4g} {supply:>4g} {movement:<9} {max(r.time_scale for r in rs):>5.2f}  "
                     f"{cells}   {' '.join(f'{v:4.1f}' for v in largest)}   {faults}")
    return "\n".join(lines)
