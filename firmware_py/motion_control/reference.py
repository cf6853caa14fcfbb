"""The joint reference of every cycle: a trajectory being played, or a position held.

A trajectory's clock is integer ticks (time_scaling.Clock): at full speed t = (cycle - start)
T, not an accumulated float; slowed online, a rule a log replays. So a log's analysis can
rebuild the very same reference from the waypoints, the acknowledgements and the frames it
holds (hil/reference_rebuild.py). In place on arrays made here.
"""

from __future__ import annotations

import numpy as np

from firmware_py.motion_control.time_scaling import DISABLED, Clock, ScalingRule
from firmware_py.motion_control.trajectory import T_START, TM, JointTrajectory, sls_coefficients, through_points


class Reference:
    def __init__(self, n_legs: int, period_s: float, max_segments: int, rule: ScalingRule = DISABLED):
        self.period_s = period_s
        self.clock = Clock(rule, n_legs)
        self.yr = np.zeros(n_legs)               # position [m]
        self.vr = np.zeros(n_legs)               # velocity [m/s]
        self.ar = np.zeros(n_legs)               # acceleration [m/s^2]
        self.hold_position = np.zeros(n_legs)
        self.trajectory: JointTrajectory | None = None
        self.start_cycle = 0
        self.seqs: list[int] = []                # the waypoint SEQ of each segment (CTRL_STATUS)
        self.ends = np.full(max_segments, np.inf)     # end time of each segment
        self.segments = 0
        self._segment = 0
        self.active_waypoint = 0
        self._end = np.zeros(n_legs)
        self._scratch = (np.zeros(n_legs), np.zeros(n_legs))

    @property
    def moving(self) -> bool:
        return self.trajectory is not None

    def play(self, trajectory: JointTrajectory, seqs: list[int], cycle: int) -> None:
        """Follow `trajectory` from `cycle` on; `seqs` name its segments."""
        self.trajectory = trajectory
        self.start_cycle = cycle
        self.clock.start(not trajectory.step)
        self.seqs = seqs
        seg = trajectory.segments[:, 0]
        n = len(seg)
        if n > len(self.ends):
            self.ends = np.full(n, np.inf)
        np.add(seg[:, T_START], seg[:, TM], out=self.ends[:n])
        self.ends[n:] = np.inf
        self.segments = n
        self._segment = 0

    def move(self, start, target, speed_m_s: float, accel_time_s: float, cycle: int) -> None:
        """Point to point at `speed_m_s` on the longest leg, from `start` to `target`."""
        start = np.array(start, dtype=float)
        distance = float(np.max(np.abs(np.asarray(target) - start)))
        duration = max(distance / speed_m_s + accel_time_s, 2.0 * accel_time_s)
        self.play(through_points(np.array([start, target]), accel_time_s, duration), [self.active_waypoint], cycle)

    def stop(self, accel_time_s: float, cycle: int) -> None:
        """Decelerate from the present velocity to rest within 2 accel_time_s."""
        ta = accel_time_s
        coeffs = sls_coefficients(self.yr, self.vr, self.yr + self.vr * ta, ta, 2.0 * ta, True)
        self.play(JointTrajectory(coeffs[None]), [self.active_waypoint], cycle)

    def hold(self, position) -> None:
        """Hold `position` (the trajectory, if any, is dropped)."""
        self.hold_position[:] = position
        self.trajectory = None

    def held(self) -> None:
        """This cycle's reference: the held position, at rest."""
        self.yr[:] = self.hold_position
        self.vr.fill(0.0)
        self.ar.fill(0.0)

    def follow(self, position) -> None:
        """Valves locked: the reference follows `position` (what will be held when enabled)."""
        self.yr[:] = position
        self.vr.fill(0.0)
        self.ar.fill(0.0)
        self.hold_position[:] = position

    def advance(self, spool_sent) -> bool:
        """This cycle's point of the trajectory (`spool_sent`: the valve commands of the last
        cycle, for the clock); True when it reached its end (then held)."""
        self.clock.tick(spool_sent)
        t = self.clock.cycles() * self.period_s
        self.trajectory.evaluate_into(t, self.yr, self.vr, self.ar)
        self.clock.scale(self.vr, self.ar, self.period_s)
        while self._segment < self.segments - 1 and t >= self.ends[self._segment]:
            self._segment += 1
        if self._segment < len(self.seqs):
            self.active_waypoint = self.seqs[self._segment]
        if t >= self.ends[self.segments - 1]:
            self.hold(self.yr)
            return True
        return False

    def target(self) -> np.ndarray:
        """Where the trajectory being played ends."""
        self.trajectory.evaluate_into(1e9, self._end, *self._scratch)
        return self._end.copy()
