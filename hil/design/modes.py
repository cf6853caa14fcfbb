"""The emulated hexapod's linearised modes: the design basis of its motion control.

The model is a linearisation of the emulator's own equations at a platform pose held at
rest (no re-derivation):

- mechanism: MuJoCo's 6-UPS reduced to the six leg strokes q. N = d qpos / d q (finite
  differences of `Mechanism.set_pose` through the pose), the joint-space inertia
  M_q = N^T M N from MuJoCo's inverse dynamics (columns: the forces for q'' = e_j minus the
  static ones), the gravity stiffness K_g = d F_static / d q;
- actuators: per leg, the chamber rates of `hydraulics.pressure_rates` differentiated in
  PA, PB, the leg velocity and the spool, at the pressures and spool offset that hold the
  leg's static force (`hydraulics.steady_state`); the seals' friction with its viscous
  slope (the sliding regime of the movements; the pre-sliding bristles act below 0.1 mm);
  the spool's first-order lag.

State [q (6), q' (6), PA (6), PB (6), spool (6)], input the valve command per leg (fraction of
full input): x' = A x + B u. A mode is an eigenvalue with its eigenvector's leg part mapped to
the platform (dq = J dpose): its frequency, damping ratio and the platform motion it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numba
import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.signal import cont2discrete
from scipy.spatial.transform import Rotation

from physics import hydraulics as hy
from physics import lugre
from physics.constants import BAR, MM
from plant_emulator.params import EmulatorConfig
from plant_emulator.rigs import HexapodRig

N_LEGS = 6
POSE_STEP = 1e-6                      # finite-difference step of the pose: m and rad
AXES = ("x", "y", "z", "roll", "pitch", "yaw")


def blocks(n_legs: int) -> tuple[slice, ...]:
    """The state's blocks q, q', PA, PB, spool for n legs."""
    return tuple(slice(k * n_legs, (k + 1) * n_legs) for k in range(5))


@dataclass
class Mode:
    eigenvalue: complex
    frequency_hz: float                # |lambda| / 2 pi (an oscillation's undamped frequency)
    damping_ratio: float               # -Re lambda / |lambda| (1 for a real pole)
    shape: np.ndarray                  # (6,) platform motion: x, y, z [m], roll, pitch, yaw [rad], unit peak
    leg_shape: np.ndarray              # (6,) leg strokes, unit peak
    axis: str                          # the platform axis it moves most (rotations scaled by the radius)
    platform_share: float              # leg motion vs oil-column compression in the eigenvector (0..1)

    @property
    def oscillating(self) -> bool:
        return abs(self.eigenvalue.imag) > 1e-9

    def as_dict(self) -> dict:
        return {"frequency_hz": round(self.frequency_hz, 4), "damping_ratio": round(self.damping_ratio, 4),
                "eigenvalue": [round(self.eigenvalue.real, 4), round(self.eigenvalue.imag, 4)],
                "axis": self.axis, "platform_share": round(self.platform_share, 4),
                "shape": [round(float(v), 4) for v in self.shape],
                "leg_shape": [round(float(v), 4) for v in self.leg_shape]}


@dataclass
class ModalModel:
    position_m: np.ndarray
    rpy_rad: np.ndarray
    payload_kg: float
    supply_pa: float
    strokes_m: np.ndarray              # (6,)
    static_force_n: np.ndarray         # (6,) hydraulic force holding the pose
    pressure_a_pa: np.ndarray
    pressure_b_pa: np.ndarray
    spool_offset: np.ndarray           # fraction of full input
    jacobian: np.ndarray               # (6, 6) d strokes / d pose (pose: x, y, z, rotation vector)
    joint_inertia_kg: np.ndarray       # (6, 6) M_q
    gravity_stiffness_n_m: np.ndarray  # (6, 6) K_g
    stiffness_n_m: np.ndarray          # (6,) hydraulic stiffness of each leg, A^2 (kA + alpha^2 kB)
    flow_gain_m_s: np.ndarray          # (6,) piston velocity per unit spool at no load change
    friction_slope_ns_m: float         # d friction / d velocity of the seals
    a: np.ndarray                      # (30, 30)
    b: np.ndarray                      # (30, 6)
    modes: list[Mode] = field(default_factory=list)
    converged: bool = True

    def platform_modes(self, count: int = 6, min_share: float = 0.5) -> list[Mode]:
        """The slowest oscillating modes that move the platform (leg part dominant; sealed
        chambers compress exactly as the legs move: share 0.5)."""
        moving = [m for m in self.modes if m.oscillating and m.platform_share >= min_share]
        return moving[:count]


def pose_quaternion(rpy_rad) -> np.ndarray:
    """(w, x, y, z) of the bus's R = Rz(yaw) Ry(pitch) Rx(roll)."""
    roll, pitch, yaw = rpy_rad
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat(scalar_first=True)


def _perturbed(quat0: np.ndarray, rotation_vector: np.ndarray) -> np.ndarray:
    return (Rotation.from_rotvec(rotation_vector) * Rotation.from_quat(quat0, scalar_first=True)).as_quat(
        scalar_first=True)


def joint_space(rig: HexapodRig, position_m, quat) -> tuple[np.ndarray, ...]:
    """At a pose at rest: strokes, static leg forces, J = d strokes / d pose, M_q and K_g
    (joint space; N = d qvel / d strokes gives M_q = N^T M N)."""
    mech = rig.mechanism
    model, data = mech.model, mech.data
    nv = model.nv
    position_m, quat = np.asarray(position_m, dtype=float), np.asarray(quat, dtype=float)

    def configuration(dpose):
        mech.set_pose(position_m + dpose[:3], _perturbed(quat, dpose[3:]))
        return data.qpos.copy()

    def static_forces(qpos):
        forces, _ = mech.inverse_forces(qpos, np.zeros(nv), np.zeros(nv))
        return forces

    qpos0 = configuration(np.zeros(6))
    strokes = data.qpos[mech.slide_qpos] + rig.home_length_m - rig.geometry.leg_min_m
    d_qpos = np.empty((nv, 6))
    d_force = np.empty((N_LEGS, 6))
    for j in range(6):
        step = np.zeros(6)
        step[j] = POSE_STEP
        plus, minus = configuration(step), configuration(-step)
        diff = np.empty(nv)
        mujoco.mj_differentiatePos(model, diff, 2 * POSE_STEP, minus, plus)
        d_qpos[:, j] = diff
        d_force[:, j] = (static_forces(plus) - static_forces(minus)) / (2 * POSE_STEP)
    jacobian = d_qpos[mech.slide_dof, :]                 # d strokes / d pose
    inverse = np.linalg.inv(jacobian)
    n_mat = d_qpos @ inverse                            # qvel per unit stroke rate
    static = static_forces(qpos0)
    inertia = np.empty((N_LEGS, N_LEGS))
    for j in range(N_LEGS):
        inertia[:, j] = mech.inverse_forces(qpos0, np.zeros(nv), n_mat[:, j])[0] - static
    inertia = 0.5 * (inertia + inertia.T)
    gravity_stiffness = d_force @ inverse
    mech.set_pose(position_m, quat)
    return strokes, static, jacobian, inertia, gravity_stiffness


def actuator_partials(cfg: EmulatorConfig, y: float, pa: float, pb: float, spool: float, supply_pa: float,
                      ports: float = 1.0) -> np.ndarray:
    """(2, 4) d(PA', PB') / d(v, PA, PB, spool) of `hydraulics.pressure_rates`, central differences
    (`ports` 0: the load-holding valves closed, the chambers sealed)."""
    x0 = np.array([0.0, pa, pb, spool])
    steps = np.array([1e-6, 10.0, 10.0, 1e-7])
    out = np.empty((2, 4))
    for j in range(4):
        dx = np.zeros(4)
        dx[j] = steps[j]
        hi = hy.pressure_rates(y, *(x0 + dx), supply_pa, cfg.hp, ports, cfg.hp[hy.HP_SEAL_LEAK])[:2]
        lo = hy.pressure_rates(y, *(x0 - dx), supply_pa, cfg.hp, ports, cfg.hp[hy.HP_SEAL_LEAK])[:2]
        out[:, j] = (np.array(hi) - np.array(lo)) / (2 * steps[j])
    return out


def state_matrices(cfg: EmulatorConfig, inertia: np.ndarray, gravity_stiffness: np.ndarray, strokes: np.ndarray,
                   pa: np.ndarray, pb: np.ndarray, spool: np.ndarray, supply_pa: float, friction_slope: float,
                   ports: float = 1.0, seal_stiffness: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A (5n, 5n), B (5n, n) of n legs on a mechanism of joint-space inertia `inertia` (n, n);
    and per leg the hydraulic stiffness and the flow gain (piston velocity per unit spool
    with the load force held). `seal_stiffness`: the seals' bristles as a spring per leg
    (pre-sliding), `friction_slope` then their damping (each one value or one per leg)."""
    area, alpha = cfg.area_a_m2, cfg.alpha
    n = inertia.shape[0]
    Q, QD, PA, PB, SPOOL = blocks(n)
    m_inv = np.linalg.inv(inertia)
    a = np.zeros((5 * n, 5 * n))
    b = np.zeros((5 * n, n))
    a[Q, QD] = np.eye(n)
    # M_q q'' = A (PA - alpha PB) - sigma2 q' - K_g q
    a[QD, Q] = -m_inv @ (gravity_stiffness + np.diag(np.broadcast_to(seal_stiffness, (n,))))
    a[QD, QD] = -m_inv @ np.diag(np.broadcast_to(friction_slope, (n,)))
    a[QD, PA] = m_inv * area
    a[QD, PB] = -m_inv * area * alpha
    stiffness, flow_gain = np.empty(n), np.empty(n)
    for i in range(n):
        d = actuator_partials(cfg, float(strokes[i]), float(pa[i]), float(pb[i]), float(spool[i]), supply_pa, ports)
        for row, block in ((0, PA), (1, PB)):
            r = block.start + i
            a[r, QD.start + i] = d[row, 0]
            a[r, PA.start + i] = d[row, 1]
            a[r, PB.start + i] = d[row, 2]
            a[r, SPOOL.start + i] = d[row, 3]
        # force rate per unit velocity and per unit spool: F' = A (PA' - alpha PB')
        force_per_velocity = area * (d[0, 0] - alpha * d[1, 0])
        force_per_spool = area * (d[0, 3] - alpha * d[1, 3])
        stiffness[i] = -force_per_velocity
        flow_gain[i] = force_per_spool / stiffness[i]
    tau = cfg.hp[hy.HP_TAU_SPOOL]
    a[SPOOL, SPOOL] = -np.eye(n) / tau
    b[SPOOL, :] = np.eye(n) / tau
    return a, b, stiffness, flow_gain


def modes_of(a: np.ndarray, jacobian: np.ndarray, radius_m: float, area_m2: float, alpha: float,
             stiffness_n_m: np.ndarray) -> list[Mode]:
    """Every eigenvalue (one of each complex pair) with its platform motion, slowest first."""
    values, vectors = np.linalg.eig(a)
    inverse = np.linalg.inv(jacobian)
    Q, _, PA, PB, _ = blocks(jacobian.shape[0])
    out = []
    for k in np.argsort(np.abs(values)):
        lam = values[k]
        if lam.imag < -1e-9:
            continue
        vec = vectors[:, k]
        legs = vec[Q]
        # the legs' motion against the oil columns' compression (force change / stiffness)
        leg_size = np.linalg.norm(legs)
        compression = np.linalg.norm(area_m2 * (vec[PA] - alpha * vec[PB]) / stiffness_n_m)
        share = leg_size / (leg_size + compression) if leg_size + compression > 0 else 0.0
        pose = inverse @ legs
        phase = pose[np.argmax(np.abs(pose))]
        phase = phase / abs(phase) if abs(phase) > 0 else 1.0
        pose = np.real(pose / phase)
        legs_real = np.real(legs / phase)
        scaled = np.abs(pose) * np.r_[1.0, 1.0, 1.0, radius_m, radius_m, radius_m]
        peak = np.max(np.abs(pose)) or 1.0
        leg_peak = np.max(np.abs(legs_real)) or 1.0
        magnitude = abs(lam)
        out.append(Mode(complex(lam), magnitude / (2 * math.pi), float(-lam.real / magnitude) if magnitude else 1.0,
                        pose / peak, legs_real / leg_peak, AXES[int(np.argmax(scaled))], float(share)))
    return out


def modal_model(cfg: EmulatorConfig, position_m, rpy_rad=(0.0, 0.0, 0.0), payload_kg: float = 0.0,
                supply_pa: float | None = None, sealed_side: int = 0) -> ModalModel:
    """The linearised hexapod at a pose held at rest (see the module docstring). `sealed_side`
    +1 or -1: the valves in HOLD with the load-holding valves closed and the seals in
    pre-sliding, their bristles deflected to that side (LuGre's sigma0, sigma1 of that side):
    what a small push then meets."""
    return modal_models(cfg, position_m, rpy_rad, payload_kg, supply_pa, (sealed_side,))[0]


def _seal_terms(fp: np.ndarray, sealed_side: int) -> tuple[float, float, float]:
    """(ports, the seals' stiffness, their damping slope) of `modal_model`'s `sealed_side`."""
    if not sealed_side:                  # valves open, seals sliding: their viscous slope
        return 1.0, 0.0, 0.5 * (fp[lugre.S2_POS] + fp[lugre.S2_NEG])
    if sealed_side > 0:
        return 0.0, fp[lugre.S0_POS], fp[lugre.S1_POS] + fp[lugre.S2_POS]
    return 0.0, fp[lugre.S0_NEG], fp[lugre.S1_NEG] + fp[lugre.S2_NEG]


def modal_models(cfg: EmulatorConfig, position_m, rpy_rad, payload_kg: float, supply_pa: float | None,
                 sealed_sides) -> list[ModalModel]:
    """`modal_model` for each of `sealed_sides`, from one linearisation of the mechanism and
    one solve of the holding points (what the sides share)."""
    supply = cfg.actuator.supply_pressure_pa if supply_pa is None else float(supply_pa)
    rig = HexapodRig(cfg)
    rig.set_load(payload_kg)
    quat = pose_quaternion(rpy_rad)
    strokes, static, jacobian, inertia, gravity_stiffness = joint_space(rig, position_m, quat)
    pa, pb, spool = np.empty(N_LEGS), np.empty(N_LEGS), np.empty(N_LEGS)
    converged = True
    for i in range(N_LEGS):
        pa[i], pb[i], spool[i], ok = hy.steady_state(float(strokes[i]), float(static[i]), supply, cfg.hp)
        converged = converged and ok
    radius = float(np.linalg.norm(rig.geometry.platform_anchor_m[0]))
    models = []
    for side in sealed_sides:
        ports, seal_stiffness, friction_slope = _seal_terms(cfg.friction.vector, side)
        a, b, stiffness, flow_gain = state_matrices(cfg, inertia, gravity_stiffness, strokes, pa, pb, spool, supply,
                                                    friction_slope, ports, seal_stiffness)
        model = ModalModel(np.asarray(position_m, dtype=float), np.asarray(rpy_rad, dtype=float), float(payload_kg),
                           supply, strokes, static, pa, pb, spool, jacobian, inertia, gravity_stiffness, stiffness,
                           flow_gain, friction_slope, a, b, converged=converged)
        model.modes = modes_of(a, jacobian, radius, cfg.area_a_m2, cfg.alpha, stiffness)
        models.append(model)
    return models


def sealed_modes(cfg: EmulatorConfig, position_m, rpy_rad=(0.0, 0.0, 0.0), payload_kg: float = 0.0,
                 count: int = 6, supply_pa: float | None = None) -> list[dict]:
    """The platform's modes with the valves in HOLD (chambers sealed), for a small push: the
    seals' bristles swing from one side to the other every half period, so each mode is the
    model's with either side's bristles, each for half a period: frequency 2 / (1/f+ + 1/f-),
    damping ratio the mean. Paired one to one by the legs' mode shapes. (A push on a
    platform whose bristles hold a force: `sealed_response`.)"""
    plus, minus = (model.platform_modes(count, 0.45)
                   for model in modal_models(cfg, position_m, rpy_rad, payload_kg, supply_pa, (1, -1)))
    similarity = np.array([[abs(float(np.dot(p.leg_shape, m.leg_shape))) for m in minus] for p in plus])
    rows, cols = linear_sum_assignment(-similarity)
    out = []
    for row, col in sorted(zip(rows, cols)):
        mode, other = plus[row], minus[col]
        out.append({"axis": mode.axis, "frequency_hz": 2.0 / (1.0 / mode.frequency_hz + 1.0 / other.frequency_hz),
                    "damping_ratio": 0.5 * (mode.damping_ratio + other.damping_ratio),
                    "frequency_hz_sides": (mode.frequency_hz, other.frequency_hz),
                    "damping_ratio_sides": (mode.damping_ratio, other.damping_ratio),
                    "shape": mode.shape})
    return out


@numba.njit(cache=True)
def _sealed_steps(phi, gamma, friction, rest_force_n, z, push_forces, push_steps, steps, step_s, every,
                  stroke_of_pose, q_start, qd_start, out):
    """The sealed linear plant (x+ = phi x + gamma u, u the legs' forces) with each seal's
    bristles integrated by the emulator's LuGre law (`lugre.force_split`, `lugre.z_step`):
    every `every` steps the platform's coordinate `stroke_of_pose` . q into `out`."""
    n_legs = z.shape[0]
    x = np.zeros(phi.shape[0])
    u = np.zeros(n_legs)
    sample = 0
    for k in range(steps):
        for i in range(n_legs):
            v = x[qd_start + i]
            z_force, slope = lugre.force_split(z[i], v, friction)
            u[i] = rest_force_n[i] - z_force - slope * v + (push_forces[i] if k < push_steps else 0.0)
        x = phi @ x + gamma @ u
        for i in range(n_legs):
            z[i] = lugre.z_step(z[i], x[qd_start + i], step_s, friction)
        if (k + 1) % every == 0 and sample < out.shape[0]:
            y = 0.0
            for i in range(n_legs):
                y += stroke_of_pose[i] * x[q_start + i]
            out[sample] = y
            sample += 1


def sealed_response(cfg: EmulatorConfig, position_m, pressures_pa, axis: int, push: float, push_s: float,
                    observe_s: float, payload_kg: float = 0.0, rpy_rad=(0.0, 0.0, 0.0), period_s: float = 0.002,
                    step_s: float = 5e-5) -> np.ndarray:
    """The sealed platform's response to a push (`push` N, or N m about axes 3-5, for `push_s`),
    sampled every `period_s` for `push_s + observe_s`: the pose coordinate `axis` from rest [m
    or rad]. The mechanism and oil columns linearised at the pose and at `pressures_pa` (PA, PB
    per leg, the sealed chambers), each seal's bristles nonlinear: LuGre's law as the emulator
    integrates it, starting from the force they hold there (the chambers' force less the
    mechanism's static load). A deflected bristle relaxes with every swing, a loss linear in
    the amplitude that no linearised seal holds (docs/MEASUREMENTS.md "Hexapod modes")."""
    rig = HexapodRig(cfg)
    rig.set_load(payload_kg)
    strokes, static, jacobian, inertia, gravity_stiffness = joint_space(rig, position_m, pose_quaternion(rpy_rad))
    pa, pb = (np.asarray(p, dtype=float) for p in pressures_pa)
    rest = cfg.area_a_m2 * (pa - cfg.alpha * pb) - static         # what the bristles hold
    a, _, _, _ = state_matrices(cfg, inertia, gravity_stiffness, strokes, pa, pb, np.zeros(N_LEGS),
                                cfg.actuator.supply_pressure_pa, 0.0, 0.0)   # the seals' force comes from the law below
    n = a.shape[0]
    q, qd = blocks(N_LEGS)[:2]
    b = np.zeros((n, N_LEGS))
    b[qd, :] = np.linalg.inv(inertia)
    phi, gamma, *_ = cont2discrete((a, b, np.eye(n), np.zeros((n, N_LEGS))), step_s, method="zoh")
    fp = cfg.friction.vector
    z = np.array([f / (fp[lugre.S0_POS] if f >= 0.0 else fp[lugre.S0_NEG]) for f in rest])
    wrench = np.zeros(6)
    wrench[axis] = push
    out = np.full(int(round((push_s + observe_s) / period_s)), np.nan)
    _sealed_steps(np.ascontiguousarray(phi), np.ascontiguousarray(gamma), fp, rest, z,
                  np.linalg.solve(jacobian.T, wrench), int(round(push_s / step_s)),
                  int(round((push_s + observe_s) / step_s)), step_s, int(round(period_s / step_s)),
                  np.ascontiguousarray(np.linalg.inv(jacobian)[axis]), q.start, qd.start, out)
    return out


def model_doc(model: ModalModel, count: int = 6) -> dict:
    """The JSON form (thesis units at the edge: mm, deg, bar)."""
    return {
        "pose": {"position_mm": [round(v / MM, 3) for v in model.position_m],
                 "rpy_deg": [round(math.degrees(v), 4) for v in model.rpy_rad]},
        "payload_kg": model.payload_kg, "supply_bar": round(model.supply_pa / BAR, 3),
        "converged": model.converged,
        "legs": {"stroke_mm": [round(v / MM, 3) for v in model.strokes_m],
                 "static_force_n": [round(float(v), 3) for v in model.static_force_n],
                 "pressure_a_bar": [round(v / BAR, 3) for v in model.pressure_a_pa],
                 "pressure_b_bar": [round(v / BAR, 3) for v in model.pressure_b_pa],
                 "spool_offset_pct": [round(v * 100, 4) for v in model.spool_offset],
                 "stiffness_n_mm": [round(v * MM, 3) for v in model.stiffness_n_m],
                 "flow_gain_mm_s_per_pct": [round(v / MM / 100, 4) for v in model.flow_gain_m_s],
                 "joint_inertia_diagonal_kg": [round(float(v), 3) for v in np.diag(model.joint_inertia_kg)]},
        "friction_slope_ns_mm": round(model.friction_slope_ns_m * MM, 5),
        "platform_modes": [m.as_dict() for m in model.platform_modes(count)],
        "modes": [m.as_dict() for m in model.modes],
    }


def movement_waypoints() -> dict[str, np.ndarray]:
    """Home and every waypoint of both movements of the thesis (chapter 11.3), by movement."""
    from firmware_py.mechanics.geometry import default_geometry
    from hil.experiments import MOTIONS
    geometry = default_geometry()
    return {name: motion(geometry).waypoints() for name, motion in MOTIONS.items()}


def along_movements(cfg: EmulatorConfig, payload_kg: float = 0.0, supply_pa: float | None = None) -> dict:
    """The platform modes at home and at every waypoint of both movements of the thesis."""
    return {name: [model_doc(modal_model(cfg, point, payload_kg=payload_kg, supply_pa=supply_pa))
                   for point in points] for name, points in movement_waypoints().items()}


def format_modes(doc: dict) -> str:
    """The modes of one pose as a text table (thesis units)."""
    pose, legs = doc["pose"], doc["legs"]
    lines = [f"hexapod at {', '.join(f'{v:g}' for v in pose['position_mm'])} mm, "
             f"rpy {', '.join(f'{v:g}' for v in pose['rpy_deg'])} deg; payload {doc['payload_kg']:g} kg, "
             f"supply {doc['supply_bar']:g} bar" + ("" if doc["converged"] else " (operating point NOT converged)"),
             "leg  stroke mm  force N  PA bar  PB bar  spool %  stiffness N/mm  flow gain mm/s/%  M_qq kg"]
    for i in range(len(legs["stroke_mm"])):
        lines.append(f"{i + 1:3d}  {legs['stroke_mm'][i]:9.1f}  {legs['static_force_n'][i]:7.1f}  "
                     f"{legs['pressure_a_bar'][i]:6.2f}  {legs['pressure_b_bar'][i]:6.2f}  "
                     f"{legs['spool_offset_pct'][i]:7.3f}  {legs['stiffness_n_mm'][i]:14.2f}  "
                     f"{legs['flow_gain_mm_s_per_pct'][i]:16.2f}  {legs['joint_inertia_diagonal_kg'][i]:7.1f}")
    lines.append("modes (slowest first; real poles have damping 1, unstable ones a negative one):")
    lines.append("  f Hz      zeta   axis   legs share  shape x y z [m] roll pitch yaw [rad], unit peak")
    for m in doc["modes"]:
        if m["platform_share"] < 0.5:
            continue
        lines.append(f"  {m['frequency_hz']:7.3f}  {m['damping_ratio']:6.3f}  {m['axis']:5s}  "
                     f"{m['platform_share']:10.2f}  {' '.join(f'{v:5.2f}' for v in m['shape'])}")
    return "\n".join(lines)


def format_along(along: dict) -> str:
    lines = ["slowest oscillating platform modes along the movements:",
             "movement  point  x y z mm              f Hz    zeta   axis"]
    for name, docs in along.items():
        for k, doc in enumerate(docs):
            modes = doc["platform_modes"][:1]
            text = (f"{modes[0]['frequency_hz']:7.3f}  {modes[0]['damping_ratio']:6.3f}  {modes[0]['axis']}"
                    if modes else "none oscillating")
            lines.append(f"{name:9s} {k:5d}  {' '.join(f'{v:6.1f}' for v in doc['pose']['position_mm'])}  {text}")
    return "\n".join(lines)


def sealed_doc(rows: list[dict]) -> list[dict]:
    """`sealed_modes` in JSON form."""
    return [{"axis": r["axis"], "frequency_hz": round(r["frequency_hz"], 4),
             "damping_ratio": round(r["damping_ratio"], 4),
             "frequency_hz_sides": [round(f, 4) for f in r["frequency_hz_sides"]],
             "damping_ratio_sides": [round(z, 4) for z in r["damping_ratio_sides"]],
             "shape": [round(float(v), 4) for v in r["shape"]]} for r in rows]


def format_sealed(rows: list[dict]) -> str:
    lines = ["sealed (valves HOLD, the seals in pre-sliding: what a small push meets, `hil run hex-kick`):",
             "axis    f Hz   zeta   f+ / f- Hz (each bristle side)"]
    lines += [f"{r['axis']:5s} {r['frequency_hz']:6.3f} {r['damping_ratio']:6.3f}   "
              f"{r['frequency_hz_sides'][0]:.3f} / {r['frequency_hz_sides'][1]:.3f}" for r in rows]
    return "\n".join(lines)


def plot_modes(doc: dict, along: dict | None, out_dir) -> list[str]:
    """Mode frequencies and damping at the pose (bars) and along the movements."""
    from pathlib import Path

    from hil.plotting import plt, save
    out_dir = Path(out_dir)
    names = []
    modes = [m for m in doc["modes"] if m["platform_share"] >= 0.5]
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    labels = [f"{m['axis']}\n{m['frequency_hz']:.2f}" for m in modes]
    axes[0].bar(range(len(modes)), [m["frequency_hz"] for m in modes])
    axes[0].set_ylabel("f [Hz]")
    axes[1].bar(range(len(modes)), [m["damping_ratio"] for m in modes])
    axes[1].set_ylabel("damping ratio")
    axes[1].set_xticks(range(len(modes)), labels, fontsize=7)
    for ax in axes:
        ax.grid(alpha=0.3)
    save(fig, out_dir / "modes.png")
    names.append("modes.png")
    if along:
        fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=False)
        for ax, (name, docs) in zip(axes, along.items()):
            for rank in range(3):
                f = [d["platform_modes"][rank]["frequency_hz"] if len(d["platform_modes"]) > rank else np.nan
                     for d in docs]
                ax.plot(range(len(docs)), f, "o-", label=f"mode {rank + 1}")
            ax.set_title(name, fontsize=9)
            ax.set_ylabel("f [Hz]")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        axes[-1].set_xlabel("waypoint")
        save(fig, out_dir / "modes_along.png")
        names.append("modes_along.png")
    return names
