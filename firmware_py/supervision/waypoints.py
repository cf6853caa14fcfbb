"""The host's waypoints: staging of the POS and ROT halves by TAG, the checks a commit
must pass (with the reason of a refusal), the queue, and the trajectory the queue's head
makes. Events, outside the steady cycle: they may allocate, the cycle does not.

Rules (docs/PROTOCOL.md): HOST_WAYPOINT_POS and _ROT are staged under their TAG;
HOST_WAYPOINT_TIME with the same TAG (= SEQ & 0xF) commits them, whatever its result
consuming the staged halves of its TAG. The first SEQ after start-up or CLEAR_WAYPOINTS is
free; then each accepted SEQ must be the previous accepted one + 1 (mod 256), and a refused
one does not count. A trajectory plays only once its LAST is queued, so a waypoint without
LAST is judged as the trajectory passes it (no stop there) and one with LAST as it ends at
rest; the queue's last place is kept for a LAST. Rigs: `testbench` (a waypoint's Z is the
stroke; X, Y and the rotation must be 0) and `hexapod` (platform poses; strokes by inverse
kinematics, the path between waypoints checked pose by pose).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_py.config import Waypoints
from firmware_py.motion_control.trajectory import JointTrajectory, hold_at, through_points
from firmware_py.supervision.capacity import LegCapacity, PlatformLoads, judge_stages, leg_loads, needed_scale_stages
from firmware_py.supervision.stages import Stages, at_once
from physics.constants import GRAVITY_M_S2
from protocol.enums import Ack, State, WaypointFlag

COMMIT_STATES = (State.IDLE, State.READY, State.RUNNING)
KNOWN_FLAGS = int(sum(WaypointFlag))         # other FLAGS bits are reserved and ignored
SAMPLES_PER_ACCEL = 8                        # the capacity check's samples per SLS acceleration time
PATH_POSES_PER_STAGE = 3                     # a staged commit checks this many poses of the path a stage
TURN_BACK_COS = -0.5                         # a chain turns back from the one before it: beyond 120 deg
HOLD_S = 0.01                                # ENABLE's hold judged over this (static: any length)


@dataclass
class Waypoint:
    seq: int
    strokes: np.ndarray          # joint targets [m]
    segment_time_s: float
    accel_time_s: float
    flags: WaypointFlag
    pose: tuple                  # (x, y, z, roll, pitch, yaw) as sent, SI
    start: np.ndarray            # the joint position its segment starts from [m]
    drawn_after_m3: float = 0.0  # the oil its segment leaves drawn from the supply (the next one's start)
    lag_after: np.ndarray | None = None   # the lag its segment leaves (`capacity.lag_of`'s state; None: none)


def refused(result: Ack) -> tuple:
    """A check's refusal: (result, no strokes, no time scale, no oil drawn, no lag)."""
    return result, None, math.nan, math.nan, None


class TestbenchCheck:
    """One leg: Z within the stroke's guard, a bounded speed, and within the leg's capacity."""

    __test__ = False             # not a pytest class despite the name

    def __init__(self, waypoints: Waypoints, stroke_margin_m: float, moving_mass_kg: float, stroke_m: float,
                 capacity: LegCapacity):
        self.waypoints, self.margin_m, self.moving_mass_kg, self.stroke_m = (waypoints, stroke_margin_m,
                                                                             moving_mass_kg, stroke_m)
        self.capacity = capacity

    def holds(self, strokes, load_kg: float) -> bool:
        """The leg holds its slide and load at rest (the full range at rest: nothing moves)."""
        loads = leg_loads(hold_at(np.asarray(strokes, float), HOLD_S), 0.0, HOLD_S, HOLD_S,
                          self.moving_mass_kg + load_kg, GRAVITY_M_S2)
        return holds(self.capacity, loads)

    def stages(self, chain: Chain, pos, rot, step: bool, load_kg: float) -> Stages[tuple]:
        """One stage: the bench's check is cheap."""
        yield from ()
        return self(chain, pos, rot, step, load_kg)

    def __call__(self, chain: Chain, pos, rot, step: bool, load_kg: float):
        margin = self.margin_m
        if max(abs(pos[0]), abs(pos[1]), *(abs(r) for r in rot)) > 1e-9 or not (
                margin <= pos[2] <= self.stroke_m - margin):
            return refused(Ack.OUTSIDE_WORKSPACE)
        strokes = np.array([pos[2]])
        if not peak_velocity_ok(self.waypoints, chain, strokes, step):
            return refused(Ack.TOO_FAST)
        if step:
            return Ack.ACCEPTED, strokes, math.nan, chain.drawn_m3, None
        trajectory, t0 = chain.trajectory(strokes)
        loads = leg_loads(trajectory, t0, chain.judged_until(trajectory), chain.sample_dt_s(),
                          self.moving_mass_kg + load_kg, GRAVITY_M_S2)
        return at_once(capacity_verdict_stages(self.waypoints, self.capacity, loads, strokes, chain))


class HexapodCheck:
    """The target and the joint-space path to it, pose by pose: reachable, away from
    singularities, a bounded joint speed, and the legs' forces along the segment's reference
    within their capacity. Compiled per pose (about 10 us each), in stages of a few tenths of
    a ms: a commit runs after the cycles' writes, stage by stage within their slack."""

    def __init__(self, waypoints: Waypoints, dk_tolerance_m: float, geometry, capacity: LegCapacity):
        from firmware_py.mechanics.kinematics import DirectKinematics
        from firmware_py.mechanics.workspace import PoseChecker
        self.waypoints, self.geometry, self.capacity = waypoints, geometry, capacity
        self.dk = DirectKinematics(geometry, dk_tolerance_m, 50)
        self.loads = PlatformLoads(geometry, dk_tolerance_m, angle_weight=waypoints.angle_weight_m_rad)
        self.poses = PoseChecker(geometry)
        self.fractions = np.linspace(1.0, 0.0, waypoints.path_samples)

    def __call__(self, chain: Chain, pos, rot, step: bool, load_kg: float):
        return at_once(self.stages(chain, pos, rot, step, load_kg))

    def holds(self, strokes, load_kg: float) -> bool:
        """The legs hold the platform at rest at `strokes` with the payload the check knows
        (its estimate); a pose it cannot place (DK lost, singular) is left to those checks."""
        try:
            loads = self.loads.loads(hold_at(np.asarray(strokes, float), HOLD_S), 0.0, HOLD_S, HOLD_S)
        except ValueError:
            return True
        return holds(self.capacity, loads)

    def stages(self, chain: Chain, pos, rot, step: bool, load_kg: float) -> Stages[tuple]:
        from firmware_py.mechanics.rotation import rpy_to_quat
        from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX, OUT_CONDITION, OUT_REACHABLE

        g = self.geometry
        target, quat = np.array(pos, dtype=float), rpy_to_quat(*rot)
        report = self.poses.check(target, quat)
        if not report[OUT_REACHABLE]:
            return refused(Ack.OUTSIDE_WORKSPACE)
        if report[OUT_CONDITION] < MIN_CONDITION_INDEX:
            return refused(Ack.SINGULAR)
        strokes = self.poses.lengths - g.leg_min_m
        if not peak_velocity_ok(self.waypoints, chain, strokes, step):
            return refused(Ack.TOO_FAST)
        # the joint-space path between the waypoints, back from the target
        dk, previous = self.dk, chain.start
        dk.pose[0:3], dk.pose[3:7] = target, quat
        singular = False
        for k, s in enumerate(self.fractions):
            if k % PATH_POSES_PER_STAGE == 0:
                yield
            dk.solve(g.leg_min_m + previous + s * (strokes - previous))
            if not dk.converged:
                return refused(Ack.OUTSIDE_WORKSPACE)
            report = self.poses.check(dk.pose[0:3], dk.pose[3:7])
            if not report[OUT_REACHABLE]:
                return refused(Ack.OUTSIDE_WORKSPACE)
            singular |= report[OUT_CONDITION] < MIN_CONDITION_INDEX
        if singular:
            return refused(Ack.SINGULAR)
        if step:
            return Ack.ACCEPTED, strokes, math.nan, chain.drawn_m3, None
        yield
        trajectory, t0 = chain.trajectory(strokes)
        yield
        try:
            loads = yield from self.loads.loads_stages(trajectory, t0, chain.judged_until(trajectory),
                                                       chain.sample_dt_s())
        except ValueError:                 # a pose between the checked ones: DK lost or singular
            return refused(Ack.SINGULAR)
        yield
        return (yield from capacity_verdict_stages(self.waypoints, self.capacity, loads, strokes, chain))


def holds(capacity: LegCapacity, loads) -> bool:
    """Every leg's static force at the hold's last sample within what it gives at rest (the
    whole range: holding leaves nothing to move; the sealed valves of HOLD hold more)."""
    return bool(np.all(capacity.utilisation(loads.static_n[-1], np.zeros(loads.static_n.shape[1])) <= 1.0))


def capacity_verdict_stages(waypoints: Waypoints, capacity: LegCapacity, loads, strokes,
                            chain: Chain) -> Stages[tuple]:
    """(ACCEPTED, strokes, NaN, the oil drawn at the segment's end, the lag it leaves), or
    (BEYOND_CAPACITY, None, the smallest time scale that fits (inf: none), NaN, None): `loads`
    along `chain`'s segment, judged from the oil the supply misses and the legs' lag when it
    starts (the motions before it), ending at rest where it is LAST."""
    loads.ends_at_rest = chain.ends
    drawn_m3, lag = chain.drawn_m3, chain.carried_lag(strokes)
    share, lag_max = waypoints.capacity_share, waypoints.lag_max_m
    verdict = yield from judge_stages(capacity, loads, 1.0, share, lag_max, drawn_m3, lag)
    if verdict.within:
        return Ack.ACCEPTED, strokes, math.nan, verdict.end_deficit_m3, verdict.end_lag
    yield
    scale = yield from needed_scale_stages(capacity, loads, share, lag_max, beyond=1.0, initial_m3=drawn_m3,
                                           initial_lag=lag)
    return Ack.BEYOND_CAPACITY, None, math.inf if math.isnan(scale) else scale, math.nan, None


@dataclass
class Chain:
    """The segment being committed and the ones queued before it that it continues (since
    the last LAST): the trajectory the controller will build from them, this segment ending
    at rest where it is LAST (`ends`) and passing its waypoint otherwise. The blend into this
    segment is judged with it."""
    points: list                   # the chain's start, then each queued waypoint's strokes
    accel_times: list
    segment_times: list
    drawn_m3: float = 0.0          # the oil the supply misses when this segment starts
    after: Waypoint | None = None  # the last waypoint of the chain this one starts as it ends (START)
    ends: bool = True              # this segment is the chain's LAST
    lag_before: np.ndarray | None = None   # the lag the segment before it in the chain leaves

    def carried_lag(self, strokes) -> np.ndarray | None:
        """The lag this segment starts with: within a chain, what the segment before it leaves;
        a chain's first, what `after`'s segment leaves, where this chain turns back (its first
        segment more than 120 deg from that one, in joint space: the same force on both sides
        of the waypoint); None otherwise (the position loop takes what is left while the legs
        turn)."""
        if len(self.points) > 1:
            return self.lag_before
        if self.after is None or self.after.lag_after is None:
            return None
        before = self.after.strokes - self.after.start
        first = np.asarray(strokes) - self.points[0]
        scale = float(np.linalg.norm(first) * np.linalg.norm(before))
        return self.after.lag_after if scale > 0.0 and float(np.dot(first, before)) < TURN_BACK_COS * scale else None

    @property
    def start(self) -> np.ndarray:
        return self.points[-1]

    def sample_dt_s(self) -> float:
        return self.accel_times[-1] / SAMPLES_PER_ACCEL

    def trajectory(self, strokes) -> tuple[JointTrajectory, float]:
        """(the chain through `strokes`, the time this segment starts in it)."""
        trajectory = through_points(np.array(self.points + [strokes]), self.accel_times, self.segment_times,
                                    end_at_rest=self.ends)
        return trajectory, float(sum(self.segment_times[:-1]))

    def judged_until(self, trajectory: JointTrajectory) -> float:
        """The end of what this commit judges: the chain's end at rest, else a sample short of
        the waypoint (the next segment is judged from there, its blend with it)."""
        return trajectory.duration_s if self.ends else trajectory.duration_s - self.sample_dt_s()


def head_length(flags) -> int:
    """How many waypoints (their FLAGS in queue order) the head trajectory takes: through the
    first LAST; 0 without one (a trajectory plays only once complete)."""
    return next((k + 1 for k, f in enumerate(flags) if f & WaypointFlag.LAST), 0)


def head_starts(flags) -> bool:
    """The head trajectory is complete and one of its waypoints is flagged START."""
    return any(f & WaypointFlag.START for f in flags[:head_length(flags)])


def peak_velocity_ok(waypoints: Waypoints, chain: Chain, strokes, step: bool) -> bool:
    """A step is bounded by its size; a segment by its peak joint velocity."""
    distance = float(np.max(np.abs(strokes - chain.start)))
    if step:
        return distance <= waypoints.step_max_m
    return distance / (chain.segment_times[-1] - chain.accel_times[-1]) <= waypoints.velocity_max_m_s


class WaypointQueue:
    def __init__(self, waypoints: Waypoints, check):
        self.capacity, self.check = waypoints.queue, check
        self.queue: list[Waypoint] = []
        self.expected_seq: int | None = None       # None: the next SEQ is free
        self._staged_pos: dict[int, tuple] = {}
        self._staged_rot: dict[int, tuple] = {}
        self.time_scale_needed = math.nan          # the last refusal's, for CTRL_ACK (NaN: none)
        self.taken_drawn_m3 = 0.0                  # the oil the last trajectory taken leaves drawn at its end
        self.taken_last: Waypoint | None = None    # ... and its last waypoint (the lag its segment leaves)
        self.generation = 0                        # +1 whenever waypoints leave the queue (taken, cleared)

    def stage_position(self, tag: int, x: float, y: float, z: float) -> None:
        self._staged_pos[tag & 0x0F] = (x, y, z)

    def stage_rotation(self, tag: int, roll: float, pitch: float, yaw: float) -> None:
        self._staged_rot[tag & 0x0F] = (roll, pitch, yaw)

    def free(self) -> int:
        return max(self.capacity - len(self.queue), 0)

    def clear(self) -> None:
        self.queue.clear()
        self.expected_seq = None
        self.generation += 1

    def commit(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int, state: State,
               previous, load_kg: float, drawn_m3: float = 0.0, running: Waypoint | None = None) -> Ack:
        """Check the staged pose with this TAG and queue it, or say why not; `previous` is the
        joint position the segment starts from, `drawn_m3` the oil the supply misses then and
        `running` the running motion's last waypoint (None: at rest), when nothing is queued
        before it (queued, the one before it leaves its own). At once."""
        return at_once(self.commit_stages(tag, seq, segment_time, accel_time, flags,
                                          lambda: (state, previous, load_kg, drawn_m3, running)))

    def commit_stages(self, tag: int, seq: int, segment_time: float, accel_time: float, flags: int,
                      context) -> Stages[Ack]:
        """`commit` in stages; `context()` gives (state, previous, load_kg, drawn_m3, running)
        as the controller sees them at that moment. Where waypoints leave the queue during the check
        (the running motion takes them, or a clear), the check starts again from what is then
        queued; a state that no longer admits commits at its end refuses it."""
        tag &= 0x0F
        self.time_scale_needed = math.nan
        pos = self._staged_pos.pop(tag, None)
        rot = self._staged_rot.pop(tag, None)
        if pos is None or rot is None or (seq & 0x0F) != tag:
            return Ack.INCOMPLETE
        known = WaypointFlag(flags & KNOWN_FLAGS)
        last, step = bool(known & WaypointFlag.LAST), bool(known & WaypointFlag.STEP)
        while True:
            state, previous, load_kg, drawn_m3, running = context()
            if self.expected_seq is not None and seq != self.expected_seq:
                return Ack.SEQUENCE_GAP
            if state not in COMMIT_STATES:
                return Ack.BAD_STATE
            if len(self.queue) >= self.capacity - (0 if last else 1):
                return Ack.QUEUE_FULL                           # the last place is kept for a LAST
            if not all(math.isfinite(v) for v in pos + rot + (segment_time, accel_time)):
                return Ack.NOT_FINITE
            if not (accel_time > 0.0 and segment_time >= 2.0 * accel_time):
                return Ack.BAD_ARGUMENT
            after_last = not self.queue or bool(self.queue[-1].flags & WaypointFlag.LAST)
            if step and not (last and after_last):
                return Ack.BAD_ARGUMENT                         # a step is a trajectory of its own
            generation = self.generation
            chain = self.chain(previous, segment_time, accel_time, last)
            chain.drawn_m3 = self.queue[-1].drawn_after_m3 if self.queue else drawn_m3
            chain.after = self.chain_after(len(chain.points) - 1, known, running)
            verdict = yield from self.check.stages(chain, pos, rot, step, load_kg)
            if self.generation == generation:
                break
        if context()[0] not in COMMIT_STATES:
            return Ack.BAD_STATE
        result, strokes, self.time_scale_needed, drawn_after, lag_after = verdict
        if result is not Ack.ACCEPTED:
            return result
        self.queue.append(Waypoint(seq, strokes, segment_time, accel_time, known, pos + rot, chain.start,
                                   drawn_after, lag_after))
        self.expected_seq = (seq + 1) % 256
        return Ack.ACCEPTED

    def chain(self, previous, segment_time: float, accel_time: float, ends: bool) -> Chain:
        """The queued waypoints this segment continues (none after a LAST), its own times, and
        whether it is the chain's LAST (`ends`)."""
        chained = []
        for w in reversed(self.queue):
            if w.flags & WaypointFlag.LAST:
                break
            chained.insert(0, w)
        if not chained:
            start = self.queue[-1].strokes if self.queue else np.asarray(previous, dtype=float)
            return Chain([start], [accel_time], [segment_time], ends=ends)
        return Chain([chained[0].start] + [w.strokes for w in chained],
                     [w.accel_time_s for w in chained] + [accel_time],
                     [w.segment_time_s for w in chained] + [segment_time], ends=ends,
                     lag_before=chained[-1].lag_after)

    def chain_after(self, queued: int, flags: WaypointFlag, running: Waypoint | None) -> Waypoint | None:
        """The waypoint a chain starts after, `queued` of its waypoints in the queue and the one
        being committed with `flags`: the last of the chain queued before it, else `running`'s,
        when it starts as that one ends (START); None otherwise."""
        first = self.queue[len(self.queue) - queued].flags if queued else flags
        if not first & WaypointFlag.START:
            return None
        before = len(self.queue) - queued - 1
        return self.queue[before] if before >= 0 else running

    def head_complete(self) -> bool:
        """The queue's head trajectory has its LAST queued (or nothing is queued): START may play it."""
        return head_length([w.flags for w in self.queue]) > 0 or not self.queue

    def head_starts_now(self) -> bool:
        """The queue's head trajectory is complete and asks to start as soon as it may (asked in
        the cycle as a motion ends: with nothing queued it makes nothing)."""
        return bool(self.queue) and head_starts([w.flags for w in self.queue])

    def take(self, start) -> tuple[JointTrajectory, list[int]] | None:
        """The trajectory of the queue's head (through its LAST waypoint) from `start`, and the
        SEQ of each segment; None when nothing complete is queued."""
        take = head_length([w.flags for w in self.queue])
        if take == 0:
            return None
        chosen, self.queue = self.queue[:take], self.queue[take:]
        self.generation += 1
        self.taken_drawn_m3 = chosen[-1].drawn_after_m3
        self.taken_last = chosen[-1]
        if chosen[0].flags & WaypointFlag.STEP:           # a step reference (chapters 5.4, 7.6.1)
            return hold_at(chosen[0].strokes, chosen[0].segment_time_s), [chosen[0].seq]
        points = np.array([start] + [w.strokes for w in chosen])
        return (through_points(points, [w.accel_time_s for w in chosen], [w.segment_time_s for w in chosen]),
                [w.seq for w in chosen])
