"""What the legs can give against what a movement asks, and the fastest timing the
controller accepts for it.

The judgement is the controller's own (`firmware_py.supervision.capacity`): each leg's force
at its velocity with the valve open and the seals' steady friction taken off, a share kept
for the control, and the lag a shortfall leaves. `utilisation` reports it over a whole
movement; `plan` finds the time scale a host sends it at: the movement's waypoints committed
to the controller's own waypoint queue and check (its `[waypoints]`, geometry and payload,
its `[hydraulic_model]` supply), and at every refusal the time scale the refusal names taken
(as a host reading CTRL_ACK's TIME_SCALE would), from the slowest the hil runs accept up; the
plan keeps EDGE_MARGIN above the edge found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.trajectory import Y0, JointTrajectory
from firmware_py.rig_model import HexapodModel
from firmware_py.supervision.capacity import PlatformLoads, judge, leg_capacity, needed_scale
from firmware_py.supervision.waypoints import WaypointQueue
from hil.design.time_optimal import time_optimal
from hil.experiments import MOTIONS, Motion, movement_waypoints
from physics.constants import BAR, CM3
from protocol.enums import Ack, State

PERIOD_S = 0.002
PLAN_SCALES = (0.5, 10.0)          # what `hil run --time-scale` accepts: the plan starts at the fastest
PLAN_ROUNDS = 24                   # refusals answered before the plan gives up
# the controller judges with its payload estimate, not the declared payload: 0.03 % above a
# declared 6 kg turned a timing at the check's edge into BEYOND_CAPACITY. The edge is accepted
# this much faster than it is sent.
PLAN_MARGIN = 1.01
# The plan keeps this much from that edge: the check's lag bound leaves the rest of the 10 mm
# to the loop's own error, which at the edge can take more (the circle with 0 kg at 40 bar ran
# 10.4 mm at its edge, 0.61 x; docs/MEASUREMENTS.md "The check's tightness").
EDGE_MARGIN = 1.02


def declared(cfg: ControllerConfig, payload_kg: float | None = None, supply_bar: float | None = None):
    """`cfg` with this payload and supply declared (None: as configured)."""
    if payload_kg is not None:
        cfg = replace(cfg, hexapod=replace(cfg.hexapod, payload_kg=payload_kg))
    if supply_bar is not None:
        cfg = replace(cfg, hydraulic_model=replace(cfg.hydraulic_model, supply_pressure_pa=supply_bar * BAR))
    return cfg


def movement(name: str, time_scale: float) -> Motion:
    """The thesis's movement (without the approach from home) at `time_scale` x its ta, tm."""
    motion = MOTIONS[name](default_geometry())
    return replace(motion, parts=motion.parts[1:]).scaled(time_scale)


def stroke_trajectory(motion: Motion, geometry) -> JointTrajectory:
    """The movement's SLS trajectory in strokes (the controller's joint coordinate)."""
    trajectory = motion.joint_trajectory(geometry)
    segments = trajectory.segments.copy()
    segments[:, :, Y0] -= geometry.leg_min_m
    return JointTrajectory(segments)


@dataclass
class Plan:
    time_scale: float                # the smallest the controller accepts (NaN: none within PLAN_SCALES)
    rounds: int                      # refusals answered on the way
    reason: str                      # the last refusal, or "" when accepted


def movement_floor(cfg: ControllerConfig, motion: Motion) -> float:
    """The smallest time scale at which the whole of `motion` after its approach from home (a
    chain of its own, from rest, at its own speed) keeps the power unit's budget and the legs'
    lag bound. The controller judges each chain of waypoints from a full
    accumulator and from legs on their reference; the host sees the chains one after the
    other: the oil one chain leaves the next, and the lag a deceleration into a waypoint
    leaves the acceleration out of it (NaN: none within the search's range)."""
    geometry = default_geometry().with_payload(cfg.hexapod.payload_kg)
    trajectory = stroke_trajectory(replace(motion, parts=motion.parts[1:]), geometry)
    loads = PlatformLoads(geometry, cfg.kinematics.dk_tolerance_m, angle_weight=cfg.waypoints.angle_weight_m_rad
                          ).loads(trajectory, 0.0, trajectory.duration_s, PERIOD_S)
    return needed_scale(leg_capacity(cfg), loads, cfg.waypoints.capacity_share, cfg.waypoints.lag_max_m)


def commit_all(cfg: ControllerConfig, motion: Motion, rig: HexapodModel | None = None
               ) -> tuple[Ack, int, np.ndarray, float]:
    """`motion`'s waypoints committed in turn to the controller's own queue and check (`cfg`
    as declared): (ACCEPTED or the first refusal, its waypoint's index, position, and the
    time scale the refusal names (NaN: none))."""
    rig = HexapodModel(cfg, PERIOD_S) if rig is None else rig
    queue = WaypointQueue(replace(cfg.waypoints, queue=255), rig.check)
    for seq, w in enumerate(movement_waypoints(motion)):
        queue.stage_position(seq, *w.position_m)
        queue.stage_rotation(seq, 0.0, 0.0, 0.0)
        result = queue.commit(seq, seq, w.segment_time_s, w.accel_time_s, w.flags, State.READY,
                              rig.home_strokes, 0.0)
        if result is not Ack.ACCEPTED:
            return result, seq, w.position_m, queue.time_scale_needed
    return Ack.ACCEPTED, -1, np.zeros(3), math.nan


def commit_both(cfg: ControllerConfig, motion: Motion, scale: float, rig: HexapodModel | None = None
                ) -> tuple[Ack, int, np.ndarray, float]:
    """`commit_all` at PLAN_MARGIN faster than `scale`, then (near its edge the check is not
    monotonic) at `scale` itself: the first refusal, or ACCEPTED."""
    rig = HexapodModel(cfg, PERIOD_S) if rig is None else rig
    verdict = commit_all(cfg, motion.scaled(scale / PLAN_MARGIN), rig)
    return verdict if verdict[0] is not Ack.ACCEPTED else commit_all(cfg, motion.scaled(scale), rig)


def accepted(cfg: ControllerConfig, motion: Motion, scale: float) -> bool:
    """The controller accepts every waypoint of `motion` at `scale` and at PLAN_MARGIN faster."""
    return commit_both(cfg, motion, scale)[0] is Ack.ACCEPTED


def plan(cfg: ControllerConfig, motion: Motion) -> Plan:
    """EDGE_MARGIN above the smallest time scale on `motion`'s ta and tm (its approach from
    home included) whose waypoints the controller's queue accepts, all of them, with `cfg` as
    declared, at it and at PLAN_MARGIN faster, and no faster than the whole movement's
    `movement_floor`; the plan is accepted too."""
    rig = HexapodModel(cfg, PERIOD_S)
    low, high = PLAN_SCALES
    floor = movement_floor(cfg, motion)
    scale, reason, edge = low, "", math.nan
    if math.isfinite(floor) and floor > low:
        scale = math.ceil(floor * 100.0) / 100.0
    for rounds in range(PLAN_ROUNDS):
        result, seq, position_m, needed = commit_both(cfg, motion, scale, rig)
        if result is Ack.ACCEPTED and math.isnan(edge):
            edge = scale                     # then the plan, EDGE_MARGIN above it, accepted as well
            scale = max(math.ceil(edge * EDGE_MARGIN * 100.0) / 100.0, edge)
            result, seq, position_m, needed = commit_all(cfg, motion.scaled(scale), rig)
        if result is Ack.ACCEPTED:
            return Plan(scale, rounds, "")
        reason = (f"waypoint {seq + 1} ({np.round(position_m * 1e3, 1).tolist()} mm) {result.name}"
                  + (f", time scale x{needed:.3f}" if result is Ack.BEYOND_CAPACITY else ""))
        if result is not Ack.BEYOND_CAPACITY or not math.isfinite(needed) or scale * needed > high:
            return Plan(math.nan, rounds + 1, reason)
        scale = math.ceil(scale * max(needed, 1.001) * 100.0) / 100.0
    return Plan(math.nan, PLAN_ROUNDS, reason)


@dataclass
class Utilisation:
    movement: str
    payload_kg: float
    supply_bar: float
    time_scale: float
    utilisation: float               # the largest force / capacity ratio over the movement and the legs
    lag_mm: float                    # the platform's largest error the shortfalls leave (share kept for control)
    at_s: float                      # where (time into the movement) ...
    leg: int                         # ... and which leg (1..6)
    deficit_cm3: float               # the oil drawn beyond the pump's share ...
    reserve_cm3: float               # ... and what the accumulator and line give for it
    whole_scale: float               # the time scale at which the whole movement's lag is within bound
    planned_scale: float             # `plan`'s: EDGE_MARGIN above what the controller accepts, waypoint by waypoint
    planned_s: float                 # the movement's duration (after its approach) at that scale
    time_optimal_s: float            # TOPP-RA's on the same path within the same share, no lag allowed

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in self.__dict__.items()}


def utilisation(cfg: ControllerConfig, name: str, payload_kg: float = 0.0, supply_bar: float | None = None,
                time_scale: float = 1.0, optimal: bool = True) -> Utilisation:
    """The movement against the legs at `time_scale`, the planned scale, and (`optimal`)
    TOPP-RA's time-optimal duration beside the planned one."""
    cfg = declared(cfg, payload_kg, supply_bar)
    geometry = default_geometry().with_payload(payload_kg)
    trajectory = stroke_trajectory(movement(name, time_scale), geometry)
    loads = PlatformLoads(geometry, cfg.kinematics.dk_tolerance_m, angle_weight=cfg.waypoints.angle_weight_m_rad
                          ).loads(trajectory, 0.0, trajectory.duration_s, PERIOD_S)
    capacity = leg_capacity(cfg)
    share, lag_max = cfg.waypoints.capacity_share, cfg.waypoints.lag_max_m
    verdict = judge(capacity, loads, 1.0, share, lag_max)
    whole = needed_scale(capacity, loads, share, lag_max) * time_scale
    thesis = MOTIONS[name](default_geometry())
    planned = plan(cfg, thesis).time_scale
    optimal = time_optimal(cfg, thesis, payload_kg) if optimal else [(math.nan, math.nan)]
    return Utilisation(name, payload_kg, cfg.hydraulic_model.supply_pressure_pa / BAR, time_scale,
                       verdict.utilisation, verdict.lag_m * 1e3, verdict.sample * PERIOD_S, verdict.leg + 1,
                       verdict.deficit_m3 / CM3, verdict.reserve_m3 / CM3, whole, planned,
                       planned * sum(sls for _, sls in optimal), sum(t for t, _ in optimal))


def format_utilisation(rows: list[Utilisation]) -> str:
    lines = ["movement  payload kg  supply bar  time scale  utilisation  error mm  where (leg, t s)  "
             "oil beyond pump / reserve cm3  whole-movement scale  planned scale  planned s  time-optimal s"]
    for r in rows:
        whole = "-" if not math.isfinite(r.whole_scale) else f"{r.whole_scale:.2f}"
        planned = "none fits" if not math.isfinite(r.planned_scale) else f"{r.planned_scale:.2f}"
        lag = "inf" if not math.isfinite(r.lag_mm) else f"{r.lag_mm:.2f}"
        seconds = "-" if not math.isfinite(r.planned_s) else f"{r.planned_s:.2f}"
        optimal = "none" if not math.isfinite(r.time_optimal_s) else f"{r.time_optimal_s:.2f}"
        lines.append(f"{r.movement:<9} {r.payload_kg:>10.1f} {r.supply_bar:>11.1f} {r.time_scale:>11.2f} "
                     f"{r.utilisation:>12.2f} {lag:>9}  leg {r.leg}, {r.at_s:5.2f} s  "
                     f"{r.deficit_cm3:>20.1f} / {r.reserve_cm3:<6.1f} {whole:>20} {planned:>14} "
                     f"{seconds:>10} {optimal:>15}")
    return "\n".join(lines)
