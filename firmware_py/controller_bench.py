"""`hydrapod controller bench`: the update step alone (supervision, reference, estimation,
control, outputs; no bus) for each controller and rig, compute time p50/p99/max.

The core runs a trajectory in RUNNING with measurements that trail the reference by one
cycle (the hexapod: the circle of chapter 11.5 through IK; the test bench: a 10 mm step
train), so every branch of the steady cycle is exercised, DK included. The first cycles
(numba compilation, caches) are excluded.
"""

from __future__ import annotations

import gc
import time

import numpy as np

from .config import ControllerConfig
from .control import CONTROLLER_NAMES
from .core import RIGS, ControllerCore
from .trajectory import circle_motion, concatenate, through_points

GOALS_US = {("hexapod", "model-based"): {"p99": 300.0, "max": 1000.0}}


def prepared_core(cfg: ControllerConfig, rig: str, controller: str, period_s: float = 0.002):
    """A core in RUNNING along a trajectory (measurements = last cycle's reference), and
    the trajectory (to replay it)."""
    core = ControllerCore(cfg, rig, period_s, CONTROLLER_NAMES[controller])
    if core.hexapod:
        circle = circle_motion(core.geometry).joint_trajectory(core.geometry)
        start, end = (np.empty(6) for _ in range(2))
        circle.evaluate_into(0.0, start, np.empty(6), np.empty(6))
        circle.evaluate_into(circle.duration_s, end, np.empty(6), np.empty(6))
        trajectory = concatenate([circle, through_points(np.array([end, start]), 0.05, 0.5)])   # closed: replayable
        trajectory.segments[:, :, 0] -= core.geometry.leg_min_m            # lengths -> strokes (Y0)
    else:
        points = np.array([[0.15], [0.16], [0.15], [0.16], [0.15]])
        trajectory = through_points(points, 0.05, 0.5)
    pos, vel, acc = (np.empty(core.n) for _ in range(3))
    trajectory.evaluate_into(0.0, pos, vel, acc)
    core.meas_y[:] = pos
    core.meas_force[:] = 20.0
    core.meas_fresh[:] = True
    core.valve_state[:] = 3
    core.update()                                   # initialises at the measured state
    core.activated(auto_enable=True)
    replay(core, trajectory)
    return core, trajectory


def replay(core: ControllerCore, trajectory) -> None:
    core.play(trajectory, [1])
    core.sup.start_running()


def step(core: ControllerCore) -> None:
    """One steady cycle: the plant 'tracks' with one cycle of lag."""
    core.meas_y[:] = core.yr
    core.update()


def run_bench(cfg: ControllerConfig, cycles: int = 20000, warmup: int = 500) -> list[dict]:
    """As the daemon runs: gc frozen and disabled while timing."""
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        return _run(cfg, cycles, warmup)
    finally:
        gc.enable()
        gc.unfreeze()


def _run(cfg: ControllerConfig, cycles: int, warmup: int) -> list[dict]:
    rows = []
    for rig in RIGS:
        for controller in CONTROLLER_NAMES:
            core, trajectory = prepared_core(cfg, rig, controller)
            for _ in range(warmup):
                step(core)
            times = np.empty(cycles)
            clock = time.perf_counter_ns
            for k in range(cycles):
                if core.trajectory is None:          # loop the trajectory
                    replay(core, trajectory)
                t0 = clock()
                step(core)
                times[k] = clock() - t0
            p50, p99 = np.percentile(times, [50, 99]) / 1e3
            row = {"rig": rig, "controller": controller, "cycles": cycles, "p50_us": round(float(p50), 1),
                   "p99_us": round(float(p99), 1), "max_us": round(float(times.max()) / 1e3, 1),
                   "state": core.state.name}
            goal = GOALS_US.get((rig, controller))
            if goal:
                row["goal_us"] = goal
                row["meets_goal"] = row["p99_us"] <= goal["p99"] and row["max_us"] <= goal["max"]
            rows.append(row)
    return rows


def format_bench(rows: list[dict]) -> str:
    lines = [f"{'rig':<10} {'controller':<12} {'p50 us':>8} {'p99 us':>8} {'max us':>8}  goal"]
    for r in rows:
        goal = ""
        if "goal_us" in r:
            goal = (f"p99 <= {r['goal_us']['p99']:g}, max <= {r['goal_us']['max']:g}: "
                    f"{'met' if r['meets_goal'] else 'NOT met'}")
        lines.append(f"{r['rig']:<10} {r['controller']:<12} {r['p50_us']:8.1f} {r['p99_us']:8.1f} {r['max_us']:8.1f}  {goal}")
    return "\n".join(lines)
