"""Performance evaluation of the direct kinematics, the procedure of thesis chapter 9.4.4.

For sampled workspace poses q: Q = IK(q); initial guesses qH (home) and q_k, k = 1, 10,
25, 50 (position moved k mm along each axis with random signs, eq. 9.19; rotation angle
moved by +/-k deg and its axis turned by +/-k deg about x and y, eq. 9.20-9.21); solve
q_D = DK(q_0, Q); report convergence C% (eq. 9.13), iterations, and accuracy Acc1/Acc2
(eq. 9.14-9.16: position error below 1e-6 mm / 1e-3 mm and roll-pitch-yaw error below
0.01 deg / 0.1 deg, as a share of the converged solves).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.kinematics import DirectKinematics, ik_batch
from firmware_py.mechanics.rotation import axis_angle_to_quat, quat_to_axis_angle, quat_to_rpy, rpy_to_quat
from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX, check_poses

GUESS_CLASSES = ("qH", "q1", "q10", "q25", "q50")
GUESS_OFFSET = {"q1": 1.0, "q10": 10.0, "q25": 25.0, "q50": 50.0}     # mm and deg
ACC1 = (1e-9, 0.01)          # metres, degrees (eq. 9.15)
ACC2 = (1e-6, 0.1)           # eq. 9.16

# Sampling box for the workspace: wider than every limit of the chosen geometry, so the
# reachable set is cut out by the workspace test alone.
SAMPLE_BOX_M = ((-0.6, 0.6), (-0.6, 0.6), (0.45, 0.87))
SAMPLE_RPY_DEG = ((-65.0, 65.0), (-65.0, 65.0), (-125.0, 125.0))


@dataclass
class GuessResult:
    guess: str
    solves: int
    convergence_pct: float
    mean_iterations: float
    std_iterations: float
    max_iterations: int
    acc1_pct: float
    acc2_pct: float
    max_position_error_mm: float
    max_orientation_error_deg: float
    mean_solve_us: float


def sample_workspace(geometry: Geometry, count: int, rng: np.random.Generator,
                     min_condition_index: float = MIN_CONDITION_INDEX):
    """`count` poses drawn uniformly from the box and RPY ranges, kept if in the usable
    workspace: reachable (chapter 9.3), on the home side of the singular surface (det Jx
    with the sign it has at home, chapter 9.6: beyond it the platform cannot be driven) and
    with 1/cond(Jx) >= min_condition_index (the rig's singularity margin; 0 disables it).
    """
    home_sign = np.sign(check_poses(geometry, geometry.home_position_m, geometry.home_quaternion).det_jx[0])
    positions, quats = [], []
    have = 0
    while have < count:
        batch = max(4 * (count - have), 1000)
        pos = np.column_stack([rng.uniform(lo, hi, batch) for lo, hi in SAMPLE_BOX_M])
        rpy = np.column_stack([np.radians(rng.uniform(lo, hi, batch)) for lo, hi in SAMPLE_RPY_DEG])
        quat = rpy_to_quat(rpy[:, 0], rpy[:, 1], rpy[:, 2])
        report = check_poses(geometry, pos, quat)
        keep = (report.reachable & (np.sign(report.det_jx) == home_sign)
                & (report.condition_index >= min_condition_index))
        positions.append(pos[keep])
        quats.append(quat[keep])
        have += int(keep.sum())
    return np.concatenate(positions)[:count], np.concatenate(quats)[:count]


def perturbed_guess(position_m, quat, offset: float, rng: np.random.Generator) -> np.ndarray:
    """q_k of chapter 9.4.4: offset k mm per axis and k deg on the rotation angle and axis."""
    signs = rng.choice((-1.0, 1.0), size=6)
    axis, angle = quat_to_axis_angle(quat)
    angle0 = angle + signs[3] * np.radians(offset)                      # eq. 9.20
    ax, ay = signs[4] * np.radians(offset), signs[5] * np.radians(offset)
    rot_x = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    rot_y = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    axis0 = rot_x @ rot_y @ axis                                        # eq. 9.21
    guess = np.empty(7)
    guess[:3] = position_m + signs[:3] * offset * 1e-3                  # eq. 9.19
    guess[3:] = axis_angle_to_quat(axis0, angle0)
    return guess


def _rpy_error_deg(true_quat, found_quat) -> float:
    diff = quat_to_rpy(found_quat) - quat_to_rpy(true_quat)
    diff = (diff + np.pi) % (2 * np.pi) - np.pi
    return float(np.degrees(np.linalg.norm(diff)))


def evaluate(geometry: Geometry, samples: int, seed: int, min_condition_index: float = MIN_CONDITION_INDEX,
             solver: DirectKinematics | None = None) -> dict:
    rng = np.random.default_rng(seed)
    positions, quats = sample_workspace(geometry, samples, rng, min_condition_index)
    lengths, _ = ik_batch(geometry, positions, quats)
    solver = solver or DirectKinematics(geometry)
    solver.solve(lengths[0], solver.home)                               # compile before timing
    results = []
    for name in GUESS_CLASSES:
        iterations = np.zeros(samples, dtype=int)
        converged = np.zeros(samples, dtype=bool)
        pos_err = np.full(samples, np.inf)
        ori_err = np.full(samples, np.inf)
        elapsed = 0.0
        for k in range(samples):
            guess = solver.home if name == "qH" else perturbed_guess(positions[k], quats[k],
                                                                   GUESS_OFFSET[name], rng)
            start = time.perf_counter()
            iterations[k] = solver.solve(lengths[k], guess, fallback=False)
            elapsed += time.perf_counter() - start
            converged[k] = solver.converged
            if converged[k]:
                pos_err[k] = np.linalg.norm(solver.pose[:3] - positions[k])
                ori_err[k] = _rpy_error_deg(quats[k], solver.pose[3:])
        n_conv = max(int(converged.sum()), 1)
        acc1 = np.sum(converged & (pos_err < ACC1[0]) & (ori_err < ACC1[1])) / n_conv
        acc2 = np.sum(converged & (pos_err < ACC2[0]) & (ori_err < ACC2[1])) / n_conv
        conv_iters = iterations[converged] if converged.any() else iterations
        results.append(GuessResult(
            guess=name, solves=samples, convergence_pct=100.0 * converged.mean(),
            mean_iterations=float(conv_iters.mean()), std_iterations=float(conv_iters.std()),
            max_iterations=int(conv_iters.max()), acc1_pct=100.0 * float(acc1), acc2_pct=100.0 * float(acc2),
            max_position_error_mm=float(pos_err[converged].max() * 1e3) if converged.any() else float("nan"),
            max_orientation_error_deg=float(ori_err[converged].max()) if converged.any() else float("nan"),
            mean_solve_us=1e6 * elapsed / samples))
    return {"samples": samples, "seed": seed, "min_condition_index": min_condition_index,
            "tolerance_m": solver.tolerance_m,
            "max_iterations": solver.max_iterations, "results": [asdict(r) for r in results]}


THESIS_TABLE_9_1 = {   # Table 9.1, for the side-by-side print (copied from thesis_tables.toml)
    "convergence_pct": [100, 99.98, 99.93, 98.89, 84.45],
    "max_iterations": [8, 32, 40, 100, 100],
    "mean_iterations": [6.2, 5.4, 5.7, 6.2, 7.2],
    "acc1_pct": [99.62, 99.20, 99.92, 98.44, 79.58],
    "acc2_pct": [100, 99.97, 99.67, 98.66, 79.76],
}


def format_evaluation(report: dict) -> str:
    lines = [f"direct kinematics over {report['samples']} workspace poses (seed {report['seed']}, "
             f"1/cond(Jx) >= {report['min_condition_index']:g}), tolerance {report['tolerance_m']:g} m, "
             f"<= {report['max_iterations']} iterations",
             f"{'guess':>5} {'C%':>8} {'(thesis)':>8} {'i mean':>7} {'(th.)':>5} {'i max':>5} {'(th.)':>5} "
             f"{'Acc1%':>7} {'(th.)':>6} {'Acc2%':>7} {'(th.)':>6} {'us/solve':>8}"]
    for k, row in enumerate(report["results"]):
        th = {key: values[k] for key, values in THESIS_TABLE_9_1.items()}
        lines.append(f"{row['guess']:>5} {row['convergence_pct']:8.3f} {th['convergence_pct']:8.2f} "
                     f"{row['mean_iterations']:7.2f} {th['mean_iterations']:5.1f} {row['max_iterations']:5d} "
                     f"{th['max_iterations']:5d} {row['acc1_pct']:7.2f} {th['acc1_pct']:6.2f} "
                     f"{row['acc2_pct']:7.2f} {th['acc2_pct']:6.2f} {row['mean_solve_us']:8.1f}")
    return "\n".join(lines)
