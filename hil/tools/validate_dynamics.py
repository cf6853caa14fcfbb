"""Validation of the controller's inverse dynamics against the MuJoCo model (chapter 10.4).

For each trajectory of Table 10.2 the platform's pose, twist and acceleration are known in
closed form (eq. 10.43-10.49). MuJoCo's answer: the leg joints' positions follow from the
pose, their rates and accelerations by a 5-point central difference, and
`Mechanism.inverse_forces` gives the actuator forces from MuJoCo's own tree dynamics and
constraint Jacobian; each side reads the geometry file with its own code. The model's
answer: `firmware_py.mechanics.dynamics.InverseDynamics`. A
forward run then drives the MuJoCo model with the model's forces plus a leg-length PD
loop, to show the forces hold the mechanism on the trajectory with the loop closed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX, check_poses
from hil.design.thesis import thesis_data
from physics.constants import MM
from plant_emulator.mechanism import Mechanism
from plant_emulator.rig_geometry import RigGeometry

DIFF_STEP_S = 1e-3
FORWARD_PD = (4.0e4, 4.0e2)      # N/m, N s/m on each leg's length error in the forward run


@dataclass(frozen=True)
class Trajectory:
    name: str
    a0_m: np.ndarray
    a1_m: float
    ur: np.ndarray
    theta0_rad: float
    up: np.ndarray
    thesis_absmax_n: float
    thesis_rel_pct: float
    w_rad_s: float
    duration_s: float

    def state(self, t: float):
        """(r, p, v, w, a, alpha) at time t (eq. 10.43-10.49)."""
        wt = self.w_rad_s * t
        w = self.w_rad_s
        r = self.a0_m - self.a1_m * np.cos(wt) * self.ur
        v = self.a1_m * w * np.sin(wt) * self.ur
        a = self.a1_m * w * w * np.cos(wt) * self.ur
        theta = self.theta0_rad * (1.0 - np.cos(wt))
        p = np.concatenate([[np.cos(theta / 2)], np.sin(theta / 2) * self.up])
        omega = self.theta0_rad * w * np.sin(wt) * self.up
        alpha = self.theta0_rad * w * w * np.cos(wt) * self.up
        return r, p, v, omega, a, alpha


def table_10_2() -> list[Trajectory]:
    data = thesis_data("table_10_2")
    return [Trajectory(row["name"], np.array(row["a0_mm"]) * MM, row["a1_mm"] * MM, np.array(row["ur"], float),
                       float(row["theta0_rad"]), np.array(row["up"], float), row["absmax_n"], row["rel_pct"],
                       data["w_rad_s"], data["duration_s"]) for row in data["trajectory"]]


@dataclass
class ValidationResult:
    name: str
    max_abs_error_n: float
    rel_error_pct: float
    max_force_n: float
    worst_time_s: float
    min_condition_index: float
    solve_residual: float
    forward_max_leg_error_mm: float       # NaN: not run, the path crosses the singular surface
    forward_max_closure_um: float
    thesis_absmax_n: float
    thesis_rel_pct: float
    crosses_singularity: bool


def _mujoco_state(mech: Mechanism, traj: Trajectory, t: float):
    """qpos, qvel, qacc of the whole MuJoCo model on the trajectory at time t."""
    m = mech.model
    r, p, v, omega, a, alpha = traj.state(t)
    h = DIFF_STEP_S
    legs = [mech.leg_coordinates(*traj.state(t + k * h)[:2]) for k in (-2, -1, 0, 1, 2)]
    leg_vel = (legs[0] - 8 * legs[1] + 8 * legs[3] - legs[4]) / (12 * h)
    leg_acc = (-legs[0] + 16 * legs[1] - 30 * legs[2] + 16 * legs[3] - legs[4]) / (12 * h * h)
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, p)
    rot = rot.reshape(3, 3)
    qpos = np.zeros(m.nq)
    qvel = np.zeros(m.nv)
    qacc = np.zeros(m.nv)
    f, fd = mech.free_qpos, mech.free_dof
    qpos[f:f + 3] = r
    qpos[f + 3:f + 7] = p
    qvel[fd:fd + 3] = v
    qvel[fd + 3:fd + 6] = rot.T @ omega          # MuJoCo: free-joint angular velocity in the body frame
    qacc[fd:fd + 3] = a
    qacc[fd + 3:fd + 6] = rot.T @ alpha
    for col, (qadr, dof) in enumerate(((mech.u1_qpos, mech.u1_dof), (mech.u2_qpos, mech.u2_dof),
                                       (mech.slide_qpos, mech.slide_dof))):
        qpos[qadr] = legs[2][:, col]
        qvel[dof] = leg_vel[:, col]
        qacc[dof] = leg_acc[:, col]
    return qpos, qvel, qacc


@dataclass
class ForceSeries:
    """Both models' actuator forces along one trajectory (N, per sample and leg)."""
    times_s: np.ndarray
    model_n: np.ndarray          # the controller's inverse dynamics (virtual work)
    mujoco_n: np.ndarray         # MuJoCo's tree dynamics and constraints
    condition: np.ndarray        # 1/cond(Jx) along it
    residual: float

    @property
    def errors_n(self) -> np.ndarray:
        return self.model_n - self.mujoco_n


def force_series(geometry: Geometry, mech: Mechanism, model: InverseDynamics, traj: Trajectory,
                 sample_dt_s: float = 0.01) -> ForceSeries:
    times = np.arange(0.0, traj.duration_s + 1e-9, sample_dt_s)
    mujoco_n = np.empty((len(times), 6))
    model_n = np.empty((len(times), 6))
    residual = 0.0
    poses = np.array([traj.state(t)[0] for t in times])
    quats = np.array([traj.state(t)[1] for t in times])
    condition = check_poses(geometry, poses, quats).condition_index
    for k, t in enumerate(times):
        qpos, qvel, qacc = _mujoco_state(mech, traj, t)
        mujoco_n[k], res = mech.inverse_forces(qpos, qvel, qacc)
        residual = max(residual, res)
        r, p, v, omega, a, alpha = traj.state(t)
        model.forces(r, p, np.concatenate([v, omega]), np.concatenate([a, alpha]))
        model_n[k] = model.force_n
    return ForceSeries(times, model_n, mujoco_n, condition, residual)


def validate(geometry: Geometry, rig: RigGeometry, traj: Trajectory, sample_dt_s: float = 0.01,
             series: list | None = None) -> ValidationResult:
    """One trajectory's comparison (its force series appended to `series` when given)."""
    mech = Mechanism(rig)
    model = InverseDynamics(geometry)
    run = force_series(geometry, mech, model, traj, sample_dt_s)
    if series is not None:
        series.append(run)
    times, forces, errors, condition, residual = run.times_s, run.mujoco_n, run.errors_n, run.condition, run.residual
    worst = np.unravel_index(np.argmax(np.abs(errors)), errors.shape)
    max_force = float(np.max(np.abs(forces)))
    if condition.min() >= MIN_CONDITION_INDEX:
        leg_err, closure = forward_run(geometry, traj, mech, model)
    else:      # the path crosses the singular surface: no forces can hold the platform there
        leg_err, closure = float("nan"), float("nan")
    return ValidationResult(
        name=traj.name, max_abs_error_n=float(np.max(np.abs(errors))),
        rel_error_pct=100.0 * float(np.max(np.abs(errors))) / max_force, max_force_n=max_force,
        worst_time_s=float(times[worst[0]]), min_condition_index=float(condition.min()), solve_residual=residual,
        forward_max_leg_error_mm=leg_err * 1e3, forward_max_closure_um=closure * 1e6,
        crosses_singularity=bool(condition.min() < MIN_CONDITION_INDEX),
        thesis_absmax_n=traj.thesis_absmax_n, thesis_rel_pct=traj.thesis_rel_pct)


def forward_run(geometry: Geometry, traj: Trajectory, mech: Mechanism, model: InverseDynamics):
    """Drive MuJoCo with the model's forces + a leg-length PD; (max leg error m, max closure m)."""
    kp, kd = FORWARD_PD
    r, p, *_ = traj.state(0.0)
    mech.set_pose(r, p)
    dt = mech.model.opt.timestep
    steps = int(round(traj.duration_s / dt))
    max_leg_error = 0.0
    max_closure = 0.0
    previous = mech.leg_lengths_m()
    for k in range(steps):
        t = k * dt
        r, p, v, omega, a, alpha = traj.state(t)
        model.forces(r, p, np.concatenate([v, omega]), np.concatenate([a, alpha]))
        target = model.lengths
        target_rate = model.jacobian @ np.concatenate([v, omega])
        lengths = mech.leg_lengths_m()
        rate = (lengths - previous) / dt if k else target_rate
        previous = lengths
        error = target - lengths
        mech.step(model.force_n + kp * error + kd * (target_rate - rate))
        max_leg_error = max(max_leg_error, float(np.max(np.abs(error))))
        max_closure = max(max_closure, mech.closure_error_m())
    return max_leg_error, max_closure


def validate_all(geometry: Geometry, rig: RigGeometry, series: list | None = None) -> list[dict]:
    """Every Table 10.2 trajectory; `geometry` and `rig` are the controller's and the plant's
    readings of the same geometry file (`series`: each one's ForceSeries appended)."""
    rows = [asdict(validate(geometry, rig, traj, series=series)) for traj in table_10_2()]
    for row in rows:              # JSON has no NaN: a forward run that was not made is null
        for key in ("forward_max_leg_error_mm", "forward_max_closure_um"):
            if row[key] != row[key]:
                row[key] = None
    return rows


def format_validation(rows: list[dict]) -> str:
    lines = ["inverse dynamics (virtual work) vs MuJoCo, Table 10.2 trajectories (w = 1 rad/s, 4 s)",
             f"{'traj':>4} {'max|dF| N':>10} {'(thesis)':>8} {'dF %':>9} {'(thesis)':>8} {'max|F| N':>9} "
             f"{'min 1/cond':>10} {'fwd leg err mm':>14} {'closure um':>10}"]
    for row in rows:
        lines.append(f"{row['name']:>4} {row['max_abs_error_n']:10.2e} {row['thesis_absmax_n']:8.2f} "
                     f"{row['rel_error_pct']:9.2e} {row['thesis_rel_pct']:8.2f} {row['max_force_n']:9.2f} "
                     f"{row['min_condition_index']:10.2e} " + (
                         f"{row['forward_max_leg_error_mm']:14.4f} {row['forward_max_closure_um']:10.3f}"
                         if row["forward_max_closure_um"] is not None else
                         f"{'(crosses the singular surface: not run)':>25}"))
    lines.append("Rx and Rz reach 90 deg (2 theta0): beyond the +/-55 deg roll workspace and through det Jx = 0 "
                 "(Rz: Fichter's singularity at yaw 90 deg); both models agree there, but the forces are unbounded.")
    return "\n".join(lines)


def plot_validation(rows: list[dict], series: list[ForceSeries], out) -> list[str]:
    """Fig. 10.3 (each trajectory's largest |dF_i| and dF_i % over time) and Figs. E.1-E.6
    (each trajectory's six forces, both models); the file names written into `out`."""
    from hil.plotting import plt, save
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for row, run in zip(rows, series):
        worst = np.max(np.abs(run.errors_n), axis=1)
        scale = np.max(np.abs(run.mujoco_n))
        axes[0].semilogy(run.times_s, np.maximum(worst, 1e-15), lw=1, label=row["name"])
        axes[1].semilogy(run.times_s, np.maximum(100.0 * worst / scale, 1e-15), lw=1, label=row["name"])
    axes[0].set_ylabel("max_i |F_i - F_i,MuJoCo| [N]")
    axes[1].set_ylabel("... / max |F| [%]")
    axes[1].set_xlabel("t [s]")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=6)
    fig.suptitle("Inverse dynamics vs MuJoCo, Table 10.2's trajectories (thesis Fig. 10.3: vs ADAMS)", fontsize=10)
    names = ["fig10_3_errors.png"]
    save(fig, out / names[0])
    for k, (row, run) in enumerate(zip(rows, series)):
        fig, ax = plt.subplots(figsize=(8, 4))
        for leg in range(6):
            line, = ax.plot(run.times_s, run.mujoco_n[:, leg], lw=2.5, alpha=0.35)
            ax.plot(run.times_s, run.model_n[:, leg], "--", lw=1, color=line.get_color(), label=f"F{leg + 1}")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("F [N] (wide: MuJoCo, dashed: the model)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=6)
        note = " (crosses the singular surface)" if row["crosses_singularity"] else ""
        ax.set_title(f"Dynamic model validation, trajectory {row['name']}{note} (thesis Fig. E.{k + 1})", fontsize=9)
        if row["crosses_singularity"]:
            ax.set_ylim(-5.0 * row["thesis_absmax_n"] * 100, 5.0 * row["thesis_absmax_n"] * 100)
        names.append(f"figE_{k + 1}_{row['name']}.png")
        save(fig, out / names[-1])
    return names
