"""`hydrapod design edge-moves`: random single moves at the capacity check's own edge.

A host with moves of its own: each move a random payload (0-6 kg) and supply (20, 25, 40
bar), declared, a start inside the thesis's workspace held 3 s, and a straight segment of
60-180 mm to a target at 0.3-0.8 m/s with a 50 or 100 ms acceleration. The segment is sent
at its own timing; where the controller refuses it BEYOND_CAPACITY it is sent again at the
time scale the refusal names (as a host reading CTRL_ACK would), and at 1.1 and 1.2 x that.
In process (`hil.in_process.InProcessLoop`), emulator ground truth: each run's largest
position error over the segment and 0.8 s after it, its largest yaw, and the fault if one
latched. What the check accepts at its edge must complete within 10 mm; how much slower is
needed where it does not is the check's optimism.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

PAYLOADS_KG = (0.0, 1.5, 3.0, 4.5, 6.0)
SUPPLIES_BAR = (20.0, 25.0, 40.0)
FACTORS = (1.0, 1.1, 1.2)              # x the time scale the refusal names
SETTLE_S, AFTER_S = 3.0, 0.8


@dataclass
class EdgeRun:
    move: int
    payload_kg: float
    supply_bar: float
    start_m: tuple
    target_m: tuple
    factor: float                      # NaN: accepted at its own timing (no edge to scale)
    time_scale: float
    fault: str
    max_error_mm: float                # the largest of x, y, z
    max_yaw_deg: float

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in self.__dict__.items()}


def random_move(rng: np.random.Generator) -> tuple:
    """(payload kg, supply bar, start, target, segment s, accel s)."""
    payload, supply = float(rng.choice(PAYLOADS_KG)), float(rng.choice(SUPPLIES_BAR))
    start = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.58, 0.72)])
    direction = rng.normal(size=3)
    target = start + direction / np.linalg.norm(direction) * rng.uniform(0.06, 0.18)
    target[:2] = np.clip(target[:2], -0.12, 0.12)
    target[2] = np.clip(target[2], 0.56, 0.76)
    accel = float(rng.choice([0.05, 0.1]))
    segment = max(float(np.linalg.norm(target - start)) / rng.uniform(0.3, 0.8) + accel, 2.2 * accel)
    return payload, supply, tuple(start), tuple(target), segment, accel


def _runs(job) -> list[EdgeRun]:
    move, (payload, supply, start, target, segment, accel), factors = job
    from hil.design.simulate import point_configs
    from hil.in_process import PERIOD_S, InProcessLoop
    from protocol.enums import Ack, State, WaypointFlag
    cfg, emulator = point_configs(payload, supply)
    alone = int(WaypointFlag.START | WaypointFlag.LAST)
    runs = []
    for factor in factors:
        loop = InProcessLoop(cfg, emulator, "computed-torque", payload, 1)
        loop.activate()
        loop.waypoint(start, 2.0, 0.5, alone)
        loop.cycles(round(SETTLE_S / PERIOD_S))
        ack, scale = loop.send_waypoint(target, segment, accel, alone), 1.0
        if ack is Ack.BEYOND_CAPACITY and math.isfinite(loop.time_scale):
            scale = loop.time_scale * factor * 1.001        # the wire's resolution: just past the edge
            ack = loop.send_waypoint(target, segment * scale, accel * scale, alone)
        if ack is not Ack.ACCEPTED:
            runs.append(EdgeRun(move, payload, supply, start, target, factor, scale, ack.name, math.nan, math.nan))
            break
        status, largest, yaw = loop.status, 0.0, 0.0
        for _ in range(round((segment * scale + AFTER_S) / PERIOD_S)):
            loop.cycle()
            position, (w, x, y, z) = loop.rig.platform_pose()
            largest = max(largest, float(np.max(np.abs(position - status.reference_pose[:3]))))
            yaw = max(yaw, abs(math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))))
            if status.state is State.FAULT:
                break
        edge = factor if scale != 1.0 else math.nan
        runs.append(EdgeRun(move, payload, supply, start, target, edge, scale, status.fault.name, largest * 1e3, yaw))
        if math.isnan(edge):
            break                                            # accepted as sent: no edge to step back from
    return runs


def edge_moves(count: int, seed: int = 1, workers: int = 2, factors=FACTORS) -> list[EdgeRun]:
    """`count` random moves (`random_move`, from `seed`), each at the check's edge x `factors`."""
    rng = np.random.default_rng(seed)
    jobs = [(k, random_move(rng), tuple(factors)) for k in range(count)]
    if workers <= 1:
        return [run for job in jobs for run in _runs(job)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return [run for runs in pool.map(_runs, jobs) for run in runs]


def format_edge_moves(runs: list[EdgeRun], worst: int = 5) -> str:
    """Per factor (and the moves accepted as sent): runs, faults, beyond 10 mm, the largest
    error and yaw; then the worst runs."""
    lines = ["at            runs  faults  > 10 mm  largest mm  largest yaw deg"]
    groups: dict[str, list[EdgeRun]] = {}
    for r in runs:
        key = "as sent" if math.isnan(r.factor) else f"edge x {r.factor:.2f}"
        groups.setdefault(key, []).append(r)
    for key, rs in sorted(groups.items()):
        ran = [r for r in rs if not math.isnan(r.max_error_mm)]
        faults = sum(r.fault != "NONE" for r in rs)
        beyond = sum(r.max_error_mm > 10.0 for r in ran)
        largest = max((r.max_error_mm for r in ran), default=math.nan)
        yaw = max((r.max_yaw_deg for r in ran), default=math.nan)
        lines.append(f"{key:<13} {len(rs):>4} {faults:>7} {beyond:>8} {largest:>11.1f} {yaw:>16.2f}")
    lines.append("worst:")
    for r in sorted(runs, key=lambda r: -r.max_error_mm if not math.isnan(r.max_error_mm) else 0.0)[:worst]:
        at = "as sent" if math.isnan(r.factor) else f"edge x {r.factor:.2f}"
        start, target = (np.round(np.array(p) * 1e3).tolist() for p in (r.start_m, r.target_m))
        lines.append(f"  move {r.move:>3}: {r.payload_kg:g} kg, {r.supply_bar:g} bar, {start} -> {target} mm, "
                     f"{at} (scale {r.time_scale:.2f}): {r.max_error_mm:.1f} mm, yaw {r.max_yaw_deg:.2f} deg, "
                     f"{r.fault}")
    return "\n".join(lines)
