"""`hydrapod controller bench`: the update step alone (supervision, reference, estimation,
control, valve commands; no bus) for each controller and rig, compute time p50/p99/max.

The controller drives the emulated rig in process (`hil.in_process`), so every branch of the
steady cycle runs on real measurements, the residuals' and DK's included: the hexapod the
circle of chapter 11.5 at twice the thesis's timing (at which the thesis's controllers
complete it too), the test bench a 10 mm step train, each replayed when it ends. Only the
controller's update is timed; the first cycles (caches) are excluded.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import replace

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.rig_model import RIGS
from hil.experiments import circle_motion, segment_time
from hil.in_process import InProcessLoop
from plant_emulator.params import EmulatorConfig
from protocol.enums import Command, State, WaypointFlag

GOALS_US = {("hexapod", "model-based"): {"p99": 300.0, "max": 1000.0},
            ("hexapod", "computed-torque"): {"p99": 300.0, "max": 1000.0}}
THESIS_CONTROLLERS = ("pi", "adaptive", "model-based")
TIME_SCALE = 2.0                         # the circle at twice the thesis's ta, tm
STEPS_M = (0.16, 0.15)                   # the test bench's train: up and down by 10 mm, 0.5 s each


class Bench:
    """A controller in RUNNING along its movement, replayed when it ends."""

    def __init__(self, cfg: ControllerConfig, emulator_cfg: EmulatorConfig, rig: str, controller: str):
        if rig == "hexapod" and controller in THESIS_CONTROLLERS:
            # their per-leg loops swing the platform past its tracking bound on the circle
            # (docs/MEASUREMENTS.md "Hexapod gains"): the bench times their update, not their tracking
            cfg = replace(cfg, limits=replace(cfg.limits, platform_error_max_m=1.0, platform_angle_max_rad=math.pi))
        self.loop = loop = InProcessLoop(cfg, emulator_cfg, controller, rig=rig)
        loop.activate(100)
        if rig == "hexapod":
            motion = circle_motion(loop.ctl.rig.geometry)
            part = motion.parts[1]                     # the circle, from its start point
            self.points = [(point, segment_time(motion, 1, part[k], point) * TIME_SCALE,
                            motion.ta_s * TIME_SCALE) for k, point in enumerate(part[1:])]
            self.approach = (part[0], 1.0, 0.2)
        else:
            self.points = [((0.0, 0.0, z), 0.5, 0.1) for z in STEPS_M]
            self.approach = None
        self.update_s = 0.0
        if self.approach is not None:
            loop.waypoint(self.approach[0], *self.approach[1:], WaypointFlag.START | WaypointFlag.LAST)
            loop.cycles(int(1.5 / 0.002))
        self.replay()

    def replay(self) -> None:
        """The movement queued again from where it ended (its last point is its first)."""
        loop = self.loop
        if loop.status.state is State.FAULT:              # a fault: recover and go on (the row reports it)
            loop.command(Command.RESET)
            loop.cycles(5)
            loop.command(Command.ENABLE)
        for k, (point, segment_s, accel_s) in enumerate(self.points):
            last = k == len(self.points) - 1
            loop.waypoint(point, segment_s, accel_s, (WaypointFlag.START | WaypointFlag.LAST) if last else 0)

    def step(self) -> float:
        """One steady cycle; the update's duration (s). The movement replays when it ends."""
        loop = self.loop
        if not loop.status.moving:
            self.replay()
        loop.sim.read(loop.meas)
        clock = time.perf_counter_ns
        t0 = clock()
        loop.ctl.update(loop.meas, loop.cmd)
        elapsed = clock() - t0
        loop.sim.write(loop.cmd)
        loop.ctl.after_write()
        loop.ctl.host.acks.clear()
        return elapsed * 1e-9


def run_bench(cfg: ControllerConfig, emulator_cfg: EmulatorConfig, cycles: int = 20000,
              warmup: int = 500) -> list[dict]:
    """As the daemon runs: gc frozen and disabled while timing."""
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        return _run(cfg, emulator_cfg, cycles, warmup)
    finally:
        gc.enable()
        gc.unfreeze()


def _run(cfg: ControllerConfig, emulator_cfg: EmulatorConfig, cycles: int, warmup: int) -> list[dict]:
    rows = []
    for rig in RIGS:
        for controller in CONTROLLER_NAMES:
            bench = Bench(cfg, emulator_cfg, rig, controller)
            for _ in range(warmup):
                bench.step()
            times = np.array([bench.step() for _ in range(cycles)]) * 1e6
            p50, p99 = np.percentile(times, [50, 99])
            status = bench.loop.status
            row = {"rig": rig, "controller": controller, "cycles": cycles, "p50_us": round(float(p50), 1),
                   "p99_us": round(float(p99), 1), "max_us": round(float(times.max()), 1),
                   "state": status.state.name, "faults": status.faults}
            goal = GOALS_US.get((rig, controller))
            if goal:
                row["goal_us"] = goal
                row["meets_goal"] = row["p99_us"] <= goal["p99"] and row["max_us"] <= goal["max"]
            rows.append(row)
    return rows


def format_bench(rows: list[dict]) -> str:
    lines = [f"{'rig':<10} {'controller':<16} {'p50 us':>8} {'p99 us':>8} {'max us':>8} {'faults':>6}  goal"]
    for r in rows:
        goal = ""
        if "goal_us" in r:
            goal = (f"p99 <= {r['goal_us']['p99']:g}, max <= {r['goal_us']['max']:g}: "
                    f"{'met' if r['meets_goal'] else 'NOT met'}")
        lines.append(f"{r['rig']:<10} {r['controller']:<16} {r['p50_us']:8.1f} {r['p99_us']:8.1f} "
                     f"{r['max_us']:8.1f} {r['faults']:6d}  {goal}")
    return "\n".join(lines)
