"""The controller's joint reference rebuilt from a log's waypoints and acknowledgements.

The controller does not transmit its reference; it follows a documented rule that a log
makes reproducible (firmware_py/motion_control/reference.py and waypoints.py):
- an accepted waypoint (CTRL_ACK, result 0) joins the queue; FLAGS bit 0 ends a trajectory,
  bit 1 starts it at once (or when the running motion ends), bit 2 makes it a step;
- a trajectory starts from the reference it replaces: the end point of the previous one;
- its clock is integer cycles: evaluated in the update of cycle k at
  t = (k + 1 - start) * T, where start = the cycle of the acknowledgement that started it,
  or the cycle after the one in which the previous trajectory reached its end;
- on the hexapod that clock slows online (firmware_py/motion_control/time_scaling.py): the
  rule is replayed on the frames it reads, VALVE_CMD's setpoints of the cycle before and
  LEG_PRESSURE's supply samples, with the run's [time_scaling] (`rule`).
The same codec decodes the same frames into the same floats and the same trajectory code
builds the same segments, so the rebuilt reference equals the controller's bit for bit
(tests/hil/test_hil_reference.py checks it against the controller).
HOME, PARK and STOP moves start from wherever the reference was; cycles after them until
the next rebuilt trajectory are NaN (unknown), as are cycles after a FAULT or ESTOP.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_py.motion_control.time_scaling import DISABLED, RATE_ONE, ScalingRule, rate_step, supply_update
from firmware_py.motion_control.trajectory import T_START, TM, JointTrajectory, hold_at, through_points
from firmware_py.supervision.waypoints import head_length, head_starts
from hil.logdata import LogData
from protocol.enums import Ack, AckKind, Command, State, WaypointFlag


@dataclass
class Motion:
    """One trajectory the controller played."""
    seqs: list[int]
    start: int                 # the controller's cycle count when it started (module docstring)
    end_cycle: int             # log cycle of the update in which it reached its end
    trajectory: JointTrajectory
    step: bool
    poses: list[tuple]         # the waypoints' poses (x, y, z, roll, pitch, yaw), SI
    times: np.ndarray | None = None    # its clock at each cycle from `start` to `end_cycle` (scaled)

    def time_at(self, cycle: int, period_s: float) -> float:
        if self.times is None:
            return (cycle + 1 - self.start) * period_s
        k = cycle - self.start
        return float(self.times[k]) if k < len(self.times) else 1e9


class ClockReplay:
    """The controller's time-scaling rule on a log: each cycle's inputs as the controller had
    them in its update (its VALVE_CMD setpoints of the cycle before, the latest LEG_PRESSURE
    supply sample of each valve up to this cycle)."""

    def __init__(self, log: LogData, n: int, rule: ScalingRule):
        self.rule, self.n_cycles = rule, log.n_cycles
        m = log.n_cycles
        spool = np.zeros((m, n))
        for leg in range(n):
            sent = np.nan_to_num(log.get(f"VALVE_CMD_{leg + 1}").per_cycle(m, "SPOOL_SETPOINT"))
            spool[1:, leg] = sent[:-1]
        self.spool_sent = spool
        latest, fresh = np.full(n, np.nan), np.zeros(n, dtype=np.bool_)
        samples = np.array([log.get(f"LEG_PRESSURE_{leg + 1}").per_cycle(m, "PS") for leg in range(n)]).T
        self.latest_pa = np.empty((m, n))
        for k in range(m):
            np.isfinite(samples[k], out=fresh)
            supply_update(samples[k], fresh, latest)
            self.latest_pa[k] = latest

    def times(self, trajectory: JointTrajectory, start: int, period_s: float) -> tuple[np.ndarray, int]:
        """(the clock at each cycle from `start` through the one that reaches the end, that
        cycle), as `Reference.advance` runs it."""
        end_t = _end_time(trajectory)
        r, rate, holding, ticks, out = self.rule, RATE_ONE, 0, 0, []
        k = start
        while True:
            if k < self.n_cycles:
                rate, holding = rate_step(rate, holding, self.latest_pa[k], self.spool_sent[k], r.supply_low_pa,
                                          r.spool_limit_counts, r.rate_min, r.slow, r.recover, r.hold)
            ticks += rate
            t = ticks / RATE_ONE * period_s
            out.append(t)
            if t >= end_t:
                return np.array(out), k
            k += 1


@dataclass
class Reference:
    yr: np.ndarray              # (n_cycles, n_joints) joint reference, m (NaN where unknown)
    motions: list[Motion]


class StrokeMap:
    """Waypoint pose -> joint strokes, as the controller computes them."""

    def __init__(self, rig: str):
        self.rig = rig
        if rig == "hexapod":
            from firmware_py.mechanics.geometry import default_geometry
            self.geometry = default_geometry()
        self.n = 6 if rig == "hexapod" else 1

    def __call__(self, pose) -> np.ndarray:
        if self.rig != "hexapod":
            return np.array([pose[2]])
        from firmware_py.mechanics.kinematics import ik_batch
        from firmware_py.mechanics.rotation import rpy_to_quat
        lengths, _ = ik_batch(self.geometry, np.array(pose[:3])[None], rpy_to_quat(*pose[3:])[None])
        return lengths[0] - self.geometry.leg_min_m


def _end_time(trajectory: JointTrajectory) -> float:
    """The trajectory's end, T_START + TM of its last segment, as the controller computes it."""
    seg = trajectory.segments[-1, 0]
    return np.add(seg[T_START], seg[TM])


def _end_cycle(trajectory: JointTrajectory, start: int, period_s: float) -> int:
    """The log cycle whose update first sees t >= the trajectory's end (same float test)."""
    end_t = _end_time(trajectory)
    k = start - 1 + max(int(math.ceil(end_t / period_s)) - 1, 0)
    while (k + 1 - start) * period_s >= end_t:
        k -= 1
    while (k + 1 - start) * period_s < end_t:
        k += 1
    return k


def rebuild(log: LogData, rig: str, period_s: float, initial_position=None,
            rule: ScalingRule | None = None) -> Reference:
    """Rebuild the reference of every cycle; `initial_position` (n_joints) starts the first motion
    when no earlier one is known (else the measured position at its start is used). `rule`:
    the run's time scaling (default: the default configuration's on the hexapod)."""
    strokes_of = StrokeMap(rig)
    n = strokes_of.n
    if rule is None:
        rule = DISABLED
        if rig == "hexapod":
            from firmware_py.config import load_config
            from firmware_py.motion_control.time_scaling import rule_of
            rule = rule_of(load_config(), period_s)
    clock = ClockReplay(log, n, rule) if rule.enabled else None
    staged_pos: dict[int, tuple] = {}
    staged_rot: dict[int, tuple] = {}
    pending: dict[int, dict] = {}      # seq -> waypoint sent, waiting for its ACK
    queue: list[dict] = []
    motions: list[Motion] = []
    running: Motion | None = None
    last_point = None if initial_position is None else np.asarray(initial_position, float)
    positions = log.leg_positions(n)

    def start(cycle_start: int, log_cycle: int):
        nonlocal queue, running, last_point
        take = head_length([w["flags"] for w in queue])
        if take == 0:
            return
        chosen, queue = queue[:take], queue[take:]
        origin = last_point if last_point is not None else positions[min(max(log_cycle, 0), len(positions) - 1)]
        if chosen[0]["flags"] & WaypointFlag.STEP:
            trajectory = hold_at(chosen[0]["strokes"], chosen[0]["segment_time"])
        else:
            points = np.array([origin] + [w["strokes"] for w in chosen])
            trajectory = through_points(points, [w["accel_time"] for w in chosen],
                                        [w["segment_time"] for w in chosen])
        step = bool(chosen[0]["flags"] & WaypointFlag.STEP)
        if clock is not None and not step:
            times, end_cycle = clock.times(trajectory, cycle_start, period_s)
        else:
            times, end_cycle = None, _end_cycle(trajectory, cycle_start, period_s)
        running = Motion([w["seq"] for w in chosen], cycle_start, end_cycle, trajectory, step,
                         [w["pose"] for w in chosen], times)
        motions.append(running)

    def starts_now() -> bool:
        return head_starts([w["flags"] for w in queue])

    def advance(to_cycle: int):
        """Play motions that end before `to_cycle`, chaining queued 'start now' trajectories."""
        nonlocal running, last_point
        while running is not None and running.end_cycle < to_cycle:
            finished = running
            running = None
            last_point = finished.trajectory.sample([1e9])[0][0]
            if starts_now():
                start(finished.end_cycle + 1, finished.end_cycle)

    unknown_from: list[int] = []
    for event in log.events:
        advance(event.cycle)
        v = event.values
        if event.name == "HOST_WAYPOINT_POS":
            staged_pos[int(v["TAG"])] = (v["X"], v["Y"], v["Z"])
        elif event.name == "HOST_WAYPOINT_ROT":
            staged_rot[int(v["TAG"])] = (v["ROLL"], v["PITCH"], v["YAW"])
        elif event.name == "HOST_WAYPOINT_TIME":
            tag = int(v["TAG"])
            pos, rot = staged_pos.pop(tag, None), staged_rot.pop(tag, None)
            if pos is not None and rot is not None:
                pending[int(v["SEQ"])] = {"seq": int(v["SEQ"]), "pose": pos + rot, "segment_time": v["SEGMENT_TIME"],
                                          "accel_time": v["ACCEL_TIME"], "flags": int(v["FLAGS"])}
        elif event.name == "HOST_CMD":
            pending[-1000 - int(v["SEQ"])] = {"command": int(v["COMMAND"])}
        elif event.name == "CTRL_ACK" and int(v["RESULT"]) == Ack.ACCEPTED:
            kind, seq = int(v["KIND"]), int(v["SEQ"])
            if kind == AckKind.WAYPOINT and seq in pending:
                w = pending.pop(seq)
                w["strokes"] = strokes_of(w["pose"])
                queue.append(w)
                if starts_now() and running is None:
                    start(event.cycle, event.cycle)
            elif kind == AckKind.HOST_CMD and (-1000 - seq) in pending:
                command = pending.pop(-1000 - seq)["command"]
                if command == Command.START and running is None:
                    start(event.cycle, event.cycle)
                elif command in (Command.HOME, Command.PARK, Command.STOP, Command.ESTOP, Command.RESET):
                    running = None
                    last_point = None
                    unknown_from.append(event.cycle)
                elif command == Command.CLEAR_WAYPOINTS:
                    queue.clear()
    advance(log.n_cycles + 10**9)
    yr = _evaluate(motions, log.n_cycles, n, period_s, unknown_from, _fault_cycles(log))
    return Reference(yr, motions)


@dataclass
class ClockAgreement:
    """The replayed clocks against the controller's own (CTRL_CLOCK, every 48th SYNC)."""
    frames: int                # CTRL_CLOCK frames of a trajectory being played, before any fault
    mismatches: int            # ... whose MOTION_TIME the replay does not give
    slowest_rate: float        # the lowest RATE the controller reported
    stretched_s: float         # how much longer the played trajectories took than their own time


def clock_agreement(log: LogData, ref: Reference, period_s: float) -> ClockAgreement:
    clock = log.get("CTRL_CLOCK")
    fault = _fault_cycles(log)
    frames = mismatches = 0
    for k, moving, motion_time in zip(clock.cycle, clock["MOVING"], clock["MOTION_TIME"]):
        if not moving or (fault is not None and k >= fault):
            continue
        playing = [m for m in ref.motions if m.start <= k <= m.end_cycle]
        frames += 1
        # CTRL_CLOCK's 1/1024-period step holds the clock exactly: the same float both ways
        mismatches += not playing or playing[-1].time_at(k, period_s) != motion_time * period_s
    slowest = float(np.min(clock["RATE"])) if len(clock) else 1.0
    stretched = sum((m.end_cycle - m.start + 1) * period_s - float(m.times[-1]) for m in ref.motions
                    if m.times is not None and (fault is None or m.end_cycle < fault))
    return ClockAgreement(frames, mismatches, slowest, stretched)


def _fault_cycles(log: LogData) -> int | None:
    status = log.get("CTRL_STATUS")
    bad = np.isin(status["STATE"], (State.FAULT, State.ESTOP))
    return int(status.cycle[np.argmax(bad)]) if bad.any() else None


def _evaluate(motions: list[Motion], n_cycles: int, n: int, period_s: float, unknown_from: list[int],
              fault_cycle: int | None) -> np.ndarray:
    yr = np.full((n_cycles, n), np.nan)
    pos, vel, acc = np.empty(n), np.empty(n), np.empty(n)
    stops = sorted(unknown_from + ([fault_cycle] if fault_cycle is not None else []))
    for k, motion in enumerate(motions):
        nxt = motions[k + 1].start if k + 1 < len(motions) else n_cycles
        later_stops = [s for s in stops if s >= motion.start]
        last = min([nxt, n_cycles] + later_stops)
        for cycle in range(max(motion.start, 0), last):
            motion.trajectory.evaluate_into(motion.time_at(cycle, period_s), pos, vel, acc)
            yr[cycle] = pos
    return yr
