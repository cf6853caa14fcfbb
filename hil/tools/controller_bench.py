"""`hydrapod controller bench`: the update step alone (supervision, reference, estimation,
control, valve commands; no bus) for each controller and rig, compute time p50/p99/max.

The controller runs a trajectory in RUNNING with measurements that trail the reference by
one cycle (the hexapod: the circle of chapter 11.5 through IK; the test bench: a 10 mm step
train), so every branch of the steady cycle is exercised, DK included. The first cycles
(numba compilation, caches) are excluded.
"""

from __future__ import annotations

import gc
import time

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.controller import RIGS, Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.motion_control.trajectory import through_points
from hil.experiments import circle_motion, concatenate

GOALS_US = {("hexapod", "model-based"): {"p99": 300.0, "max": 1000.0},
            ("hexapod", "computed-torque"): {"p99": 300.0, "max": 1000.0}}


class Bench:
    """A controller in RUNNING along a trajectory it replays, fed measurements equal to the
    last cycle's reference (the plant 'tracks' with one cycle of lag)."""

    def __init__(self, cfg: ControllerConfig, rig: str, controller: str, period_s: float = 0.002):
        self.controller = c = Controller(cfg, rig, period_s, CONTROLLER_NAMES[controller])
        self.meas, self.cmd = c.new_interfaces()
        if c.hexapod:
            circle = circle_motion(c.geometry).joint_trajectory(c.geometry)
            start, end = (np.empty(6) for _ in range(2))
            circle.evaluate_into(0.0, start, np.empty(6), np.empty(6))
            circle.evaluate_into(circle.duration_s, end, np.empty(6), np.empty(6))
            trajectory = concatenate([circle, through_points(np.array([end, start]), 0.05, 0.5)])  # closed
            trajectory.segments[:, :, 0] -= c.geometry.leg_min_m            # lengths -> strokes (Y0)
        else:
            points = np.array([[0.15], [0.16], [0.15], [0.16], [0.15]])
            trajectory = through_points(points, 0.05, 0.5)
        self.trajectory = trajectory
        pos, vel, acc = (np.empty(c.n) for _ in range(3))
        trajectory.evaluate_into(0.0, pos, vel, acc)
        self.meas.position_m[:] = pos
        self.meas.force_n[:] = 20.0
        self.meas.fresh[:] = True
        self.meas.valve_state[:] = 3
        # its plant is no hydraulics: the residuals run (their time counts), their verdict never comes
        c.residuals.persistence = c.spool_check.persistence = 1 << 62
        c.load_cells.limit = 0                          # ... nor are its constant forces a frozen load cell
        c.update(self.meas, self.cmd)                   # initialises at the measured state
        c.activated(auto_enable=True)
        self.replay()

    def replay(self) -> None:
        c = self.controller
        c.reference.play(self.trajectory, [1], c.cycles)
        c.sup.start_running()

    def step(self) -> None:
        """One steady cycle; the trajectory replays when it ends."""
        c = self.controller
        if not c.reference.moving:
            self.replay()
        self.meas.position_m[:] = c.reference.yr
        c.update(self.meas, self.cmd)


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
            bench = Bench(cfg, rig, controller)
            for _ in range(warmup):
                bench.step()
            times = np.empty(cycles)
            clock = time.perf_counter_ns
            for k in range(cycles):
                t0 = clock()
                bench.step()
                times[k] = clock() - t0
            p50, p99 = np.percentile(times, [50, 99]) / 1e3
            row = {"rig": rig, "controller": controller, "cycles": cycles, "p50_us": round(float(p50), 1),
                   "p99_us": round(float(p99), 1), "max_us": round(float(times.max()) / 1e3, 1),
                   "state": bench.controller.state.name}
            goal = GOALS_US.get((rig, controller))
            if goal:
                row["goal_us"] = goal
                row["meets_goal"] = row["p99_us"] <= goal["p99"] and row["max_us"] <= goal["max"]
            rows.append(row)
    return rows


def format_bench(rows: list[dict]) -> str:
    lines = [f"{'rig':<10} {'controller':<16} {'p50 us':>8} {'p99 us':>8} {'max us':>8}  goal"]
    for r in rows:
        goal = ""
        if "goal_us" in r:
            goal = (f"p99 <= {r['goal_us']['p99']:g}, max <= {r['goal_us']['max']:g}: "
                    f"{'met' if r['meets_goal'] else 'NOT met'}")
        lines.append(f"{r['rig']:<10} {r['controller']:<16} {r['p50_us']:8.1f} {r['p99_us']:8.1f} "
                     f"{r['max_us']:8.1f}  {goal}")
    return "\n".join(lines)
