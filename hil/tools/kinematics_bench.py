"""`hydrapod kinematics bench`: per-call time and NumPy allocations of the loop's kernels.

Goals: IK <= 20 us, DK warm-started <= 60 us, inverse dynamics
<= 150 us, 0 NumPy allocations per call. The vectorised NumPy IK on one pose is timed
beside the numba kernel to show why the loop uses the kernels.
"""

from __future__ import annotations

import gc
import time
import tracemalloc

import numpy as np

from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import N_LEGS, Geometry
from firmware_py.mechanics.kinematics import DirectKinematics, ik_batch, ik_into, jacobian_into
from hil.experiments import diagonal_motion

CYCLE_S = 0.002


def _percentiles(samples_s: list[float]) -> dict:
    us = np.asarray(samples_s) * 1e6
    return {"p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max())}


def allocations_per_call(call, repeats: int = 200) -> dict:
    """Memory behaviour of one call, after a warm-up call.

    numpy_retained: NumPy-domain blocks (tracemalloc, np.lib.tracemalloc_domain) still held
    after the calls, per call (the kernels create no arrays: numba's runtime is never asked
    for one, see the kernels' code); transient_peak_bytes: the largest traced peak above the start of a call, all
    domains (Python's call overhead included: a no-op lambda gives 0, a numba call ~400).
    """
    call()
    gc_was = gc.isenabled()
    gc.disable()
    tracemalloc.start()
    try:
        numpy_filter = [tracemalloc.DomainFilter(True, np.lib.tracemalloc_domain)]
        before = tracemalloc.take_snapshot().filter_traces(numpy_filter)
        peaks = []
        for _ in range(repeats):
            current, _ = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            call()
            peaks.append(tracemalloc.get_traced_memory()[1] - current)
        after = tracemalloc.take_snapshot().filter_traces(numpy_filter)
    finally:
        tracemalloc.stop()
        if gc_was:
            gc.enable()
    retained = sum(max(s.count_diff, 0) for s in after.compare_to(before, "traceback"))
    return {"numpy_retained_per_call": retained / repeats,
            "transient_peak_bytes": float(np.median(peaks))}


def _time(call, count: int) -> list[float]:
    out = []
    for _ in range(count):
        start = time.perf_counter_ns()
        call()
        out.append((time.perf_counter_ns() - start) * 1e-9)
    return out


def run_bench(geometry: Geometry, count: int = 20000) -> dict:
    # a realistic stream of poses: the diagonal motion sampled at the loop's period
    motion = diagonal_motion(geometry)
    joint = motion.joint_trajectory(geometry)
    times = np.arange(0.0, joint.duration_s, CYCLE_S)
    lengths_stream, _, _ = joint.sample(times)
    n = len(times)
    solver = DirectKinematics(geometry)
    poses = np.empty((n, 7))
    iterations = np.empty(n)
    for k in range(n):          # poses of the stream from the warm-started DK itself
        iterations[k] = solver.solve(lengths_stream[k])
        poses[k] = solver.pose
    base = np.ascontiguousarray(geometry.base_anchor_m)
    platform = np.ascontiguousarray(geometry.platform_anchor_m)
    rot, pw, jac = np.empty((3, 3)), np.empty((N_LEGS, 3)), np.empty((N_LEGS, 6))
    lengths, units = np.empty(N_LEGS), np.empty((N_LEGS, 3))
    index = [0]

    def ik_kernel():
        k = index[0] = (index[0] + 1) % n
        ik_into(base, platform, poses[k, :3], poses[k, 3:], rot, pw, lengths, units)
        jacobian_into(units, pw, jac)

    def ik_numpy():
        k = index[0] = (index[0] + 1) % n
        ik_batch(geometry, poses[k, :3], poses[k, 3:])

    def dk_warm():          # the motion ends where it starts, so the stream wraps smoothly
        k = index[0] = (index[0] + 1) % n
        solver.solve(lengths_stream[k])

    dyn = InverseDynamics(geometry)
    twist = np.array([0.1, -0.05, 0.08, 0.2, -0.1, 0.3])
    accel = np.array([1.0, 0.5, -2.0, 1.0, 2.0, -1.0])

    def inverse_dynamics():
        k = index[0] = (index[0] + 1) % n
        dyn.forces(poses[k, :3], poses[k, 3:], twist, accel)

    def task_space():
        k = index[0] = (index[0] + 1) % n
        dyn.task_space_terms(poses[k, :3], poses[k, 3:], twist)

    report = {"calls": count}
    for name, call in (("ik_numba", ik_kernel), ("ik_numpy_vectorised", ik_numpy), ("dk_warm", dk_warm),
                       ("inverse_dynamics", inverse_dynamics), ("task_space_terms", task_space)):
        index[0] = 0
        call()
        timing = _percentiles(_time(call, count))
        timing.update(allocations_per_call(call))
        report[name] = timing
    report["dk_warm"]["mean_iterations"] = float(np.mean(iterations[1:]))
    report["goals_us"] = {"ik_numba": 20, "dk_warm": 60, "inverse_dynamics": 150}
    return report


def format_bench(report: dict) -> str:
    lines = [f"kinematics bench: {report['calls']} calls each (pose stream: diagonal motion at 500 Hz)",
             f"{'kernel':>20} {'p50 us':>8} {'p99 us':>8} {'max us':>8} {'goal us':>8} {'numpy kept':>10} "
             f"{'peak bytes':>10}"]
    for name in ("ik_numba", "ik_numpy_vectorised", "dk_warm", "inverse_dynamics", "task_space_terms"):
        row = report[name]
        goal = report["goals_us"].get(name)
        lines.append(f"{name:>20} {row['p50_us']:8.2f} {row['p99_us']:8.2f} {row['max_us']:8.1f} "
                     f"{'' if goal is None else goal:>8} {row['numpy_retained_per_call']:10.2f} "
                     f"{row['transient_peak_bytes']:10.0f}")
    lines.append(f"DK warm start: {report['dk_warm']['mean_iterations']:.2f} iterations per solve on average")
    return "\n".join(lines)
