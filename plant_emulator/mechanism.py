"""The 6-UPS as a MuJoCo multibody model: an independent check of the controller's
kinematics and dynamics, and the mechanical half of the hexapod rig.

Model: the platform is a free body; each leg is a cylinder body hung from the base by a
universal joint (two hinges: the first about u1, fixed to the base, the second about the
leg's u2), a rod body on a slide joint along the leg axis (optionally limited to the
stroke: the cylinder's end stops, as the hexapod rig uses it), and a `connect` equality between
a site at the rod's end and a site at the platform's spherical joint (a ball joint closing
the loop). Inertias of Table 10.1 in the link frames [u4, u2, u3]. Contacts are off (the
workspace test handles collisions). The slide joints carry the actuator forces.

Only the geometry file is shared with the controller (read here by `rig_geometry`);
positions, Jacobians, mass matrices, bias forces and constraint Jacobians are MuJoCo's own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from plant_emulator.rig_geometry import RigGeometry

TIMESTEP_S = 0.0005
# Equality constraints nearly hard: impedance 0.9999 and a 2 ms reference time constant
# keep the loop-closure error in the micrometre range under the rig's forces.
CONNECT_SOLREF = "0.002 1"
CONNECT_SOLIMP = "0.9999 0.9999 0.0001 0.5 2"
# Semi-implicit Euler (joint damping implicit: the seals' friction slope). Under implicitfast
# a sealed platform carrying 6 kg at 25 bar diverged within 0.1 s, at 250 and 125 us steps
# (docs/MEASUREMENTS.md "The emulator's integrator").
INTEGRATOR = "Euler"
STOP_MARGIN_M = 0.001


def _frame(u3: np.ndarray, u1: np.ndarray) -> np.ndarray:
    """Link frame R_L = [u4, u2, u3] (eq. 10.15-10.17) as a rotation matrix."""
    u2 = np.cross(u3, u1)
    u2 /= np.linalg.norm(u2)
    u4 = np.cross(u2, u3)
    return np.column_stack([u4, u2, u3])


JOINT_LIMIT_MARGIN_RAD = math.radians(0.5)    # a hinge this close to its range is on its stop


def _quat_of(rot: np.ndarray) -> np.ndarray:
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rot.ravel())
    return quat


def _fmt(values) -> str:
    return " ".join(f"{v:.12g}" for v in np.ravel(values))


def _full_inertia(inertia: np.ndarray) -> str:
    return _fmt([inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]])


@dataclass
class LegHome:
    anchor: np.ndarray          # A_i
    frame: np.ndarray           # R_L at home
    length_m: float             # d at home


def build_mjcf(geometry: RigGeometry, timestep_s: float = TIMESTEP_S,
               joint_limits: bool = False) -> tuple[str, list[LegHome]]:
    """The 6-UPS as MJCF, and each leg's home. `joint_limits`: the rig's end stops (the
    stroke) and universal joints (each hinge within the joint's cone of the vertical leg:
    the box of the two hinges keeps the leg inside the cone, reaching it on the box's edges),
    so a lost platform stops where the rig's would instead of folding through its base."""
    home = geometry.home_position_m
    legs_home = []
    bodies = []
    for i in range(6):
        anchor = geometry.base_anchor_m[i]
        top = home + geometry.platform_anchor_m[i]
        length = float(np.linalg.norm(top - anchor))
        frame = _frame((top - anchor) / length, geometry.universal_axis[i])
        legs_home.append(LegHome(anchor.copy(), frame, length))
        axis1_local = frame.T @ geometry.universal_axis[i]
        # end stops of the stroke, 1 mm beyond it so a leg exactly at an end is not on its stop
        slide_low = geometry.leg_min_m - length - STOP_MARGIN_M
        slide_high = geometry.leg_max_m - length + STOP_MARGIN_M
        slide_range = f' range="{slide_low:.9g} {slide_high:.9g}"' if joint_limits else ""
        hinge_ranges = ("", "")
        if joint_limits:
            centre = vertical_hinges(frame, geometry.universal_axis[i])
            cone = geometry.universal_cone_rad
            hinge_ranges = tuple(f' range="{c - cone:.9g} {c + cone:.9g}"' for c in centre)
        cyl, rod = geometry.cylinder, geometry.rod
        bodies.append(f"""
    <body name="cylinder{i}" pos="{_fmt(anchor)}" quat="{_fmt(_quat_of(frame))}">
      <joint name="u1_{i}" type="hinge" axis="{_fmt(axis1_local)}"{hinge_ranges[0]}/>
      <joint name="u2_{i}" type="hinge" axis="0 1 0"{hinge_ranges[1]}/>
      <inertial pos="{_fmt(cyl.com_m)}" mass="{cyl.mass_kg:.12g}" fullinertia="{_full_inertia(cyl.inertia_kg_m2)}"/>
      <geom type="capsule" fromto="0 0 0 0 0 {geometry.cylinder_length_m:.6g}"
            size="{geometry.cylinder_radius_m:.6g}" mass="0"/>
      <body name="rod{i}" pos="0 0 {length:.12g}">
        <joint name="slide{i}" type="slide" axis="0 0 1"{slide_range}/>
        <inertial pos="{_fmt(rod.com_m)}" mass="{rod.mass_kg:.12g}" fullinertia="{_full_inertia(rod.inertia_kg_m2)}"/>
        <geom type="capsule" fromto="0 0 0 0 0 {-geometry.rod_length_m:.6g}"
              size="{geometry.rod_radius_m:.6g}" mass="0"/>
        <site name="rod_end{i}" pos="0 0 0"/>
      </body>
    </body>""")
    plat = geometry.platform
    sites = "".join(f'\n      <site name="platform_joint{i}" pos="{_fmt(geometry.platform_anchor_m[i])}"/>'
                    for i in range(6))
    connects = "".join(f'\n    <connect site1="rod_end{i}" site2="platform_joint{i}" solref="{CONNECT_SOLREF}" '
                       f'solimp="{CONNECT_SOLIMP}"/>' for i in range(6))
    motors = "".join(f'\n    <motor name="actuator{i}" joint="slide{i}" gear="1"/>' for i in range(6))
    g = geometry.gravity_m_s2
    xml = f"""<mujoco model="hydrapod-6ups">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep_s:.9g}" gravity="{_fmt(g)}" integrator="{INTEGRATOR}" solver="Newton"
          iterations="100" tolerance="1e-12">
    <flag contact="disable"/>
  </option>
  <worldbody>{''.join(bodies)}
    <body name="platform" pos="{_fmt(geometry.home_position_m)}">
      <freejoint name="platform"/>
      <inertial pos="{_fmt(plat.com_m)}" mass="{plat.mass_kg:.12g}" fullinertia="{_full_inertia(plat.inertia_kg_m2)}"/>
      <geom type="cylinder" size="{np.linalg.norm(geometry.platform_anchor_m[0]):.6g} 0.003" mass="0"/>{sites}
    </body>
  </worldbody>
  <equality>{connects}
  </equality>
  <actuator>{motors}
  </actuator>
</mujoco>
"""
    return xml, legs_home


class Mechanism:
    """The MuJoCo 6-UPS: set a platform state, step with actuator forces, inverse dynamics."""

    def __init__(self, geometry: RigGeometry, timestep_s: float = TIMESTEP_S, joint_limits: bool = False):
        self.geometry = geometry
        self.xml, self.legs_home = build_mjcf(geometry, timestep_s, joint_limits)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.free_qpos = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "platform")]
        self.free_dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "platform")]

        def joint(name):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)

        self.u1_qpos = np.array([m.jnt_qposadr[joint(f"u1_{i}")] for i in range(6)])
        self.u2_qpos = np.array([m.jnt_qposadr[joint(f"u2_{i}")] for i in range(6)])
        self.slide_qpos = np.array([m.jnt_qposadr[joint(f"slide{i}")] for i in range(6)])
        self.slide_dof = np.array([m.jnt_dofadr[joint(f"slide{i}")] for i in range(6)])
        self.u1_dof = np.array([m.jnt_dofadr[joint(f"u1_{i}")] for i in range(6)])
        self.u2_dof = np.array([m.jnt_dofadr[joint(f"u2_{i}")] for i in range(6)])
        # the hinges' ranges (limited: the rig's universal joints), each leg's u1 then u2
        self.hinge_qpos = np.concatenate([self.u1_qpos, self.u2_qpos])
        hinges = np.concatenate([[joint(f"u1_{i}") for i in range(6)], [joint(f"u2_{i}") for i in range(6)]])
        self.hinge_limited = m.jnt_limited[hinges].astype(bool)
        self.hinge_range = m.jnt_range[hinges].copy()
        self.rod_site = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"rod_end{i}") for i in range(6)])
        self.platform_site = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"platform_joint{i}")
                                       for i in range(6)])
        self.platform_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "platform")
        self.set_pose(geometry.home_position_m, np.array([1.0, 0.0, 0.0, 0.0]))

    # -- configuration ------------------------------------------------------------------

    def leg_coordinates(self, position_m, quat) -> np.ndarray:
        """(6, 3) hinge angles and slide offset of each leg for a platform pose."""
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, np.asarray(quat, dtype=float) / np.linalg.norm(quat))
        rot = rot.reshape(3, 3)
        out = np.empty((6, 3))
        for i, leg in enumerate(self.legs_home):
            top = np.asarray(position_m) + rot @ self.geometry.platform_anchor_m[i]
            length = np.linalg.norm(top - leg.anchor)
            th1, th2 = hinge_angles(leg.frame, self.geometry.universal_axis[i], (top - leg.anchor) / length)
            out[i] = (th1, th2, length - leg.length_m)
        return out

    def at_joint_limit(self, margin_rad: float = JOINT_LIMIT_MARGIN_RAD) -> bool:
        """A universal joint on (within `margin_rad` of) its cone."""
        q = self.data.qpos[self.hinge_qpos]
        low, high = self.hinge_range[:, 0], self.hinge_range[:, 1]
        return bool(np.any(self.hinge_limited & ((q <= low + margin_rad) | (q >= high - margin_rad))))

    def set_pose(self, position_m, quat) -> None:
        """Put the mechanism at a platform pose with the legs closed, at rest."""
        d = self.data
        d.qpos[self.free_qpos:self.free_qpos + 3] = position_m
        d.qpos[self.free_qpos + 3:self.free_qpos + 7] = np.asarray(quat) / np.linalg.norm(quat)
        legs = self.leg_coordinates(position_m, quat)
        d.qpos[self.u1_qpos] = legs[:, 0]
        d.qpos[self.u2_qpos] = legs[:, 1]
        d.qpos[self.slide_qpos] = legs[:, 2]
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        d.ctrl[:] = 0.0
        mujoco.mj_forward(self.model, d)

    def closure_error_m(self) -> float:
        """Largest distance between a rod end and its platform joint (loop-closure error)."""
        gap = self.data.site_xpos[self.rod_site] - self.data.site_xpos[self.platform_site]
        return float(np.max(np.linalg.norm(gap, axis=1)))

    def platform_state(self):
        """(position of P, quaternion, v of P, w, a of P, alpha) in the base frame."""
        d = self.data
        pos = d.qpos[self.free_qpos:self.free_qpos + 3].copy()
        quat = d.qpos[self.free_qpos + 3:self.free_qpos + 7].copy()
        rot = d.xmat[self.platform_body].reshape(3, 3)
        lin = d.qvel[self.free_dof:self.free_dof + 3].copy()
        ang = rot @ d.qvel[self.free_dof + 3:self.free_dof + 6]
        acc = d.qacc[self.free_dof:self.free_dof + 3].copy()
        angacc = rot @ d.qacc[self.free_dof + 3:self.free_dof + 6]
        return pos, quat, lin, ang, acc, angacc

    def leg_lengths_m(self) -> np.ndarray:
        return np.array([leg.length_m for leg in self.legs_home]) + self.data.qpos[self.slide_qpos]

    # -- dynamics -------------------------------------------------------------------------

    def step(self, force_n: np.ndarray, substeps: int = 1) -> None:
        self.data.ctrl[:] = force_n
        for _ in range(substeps):
            mujoco.mj_step(self.model, self.data)

    def inverse_forces(self, qpos, qvel, qacc) -> tuple[np.ndarray, float]:
        """Actuator forces that produce (qpos, qvel, qacc), from MuJoCo's tree dynamics.

        Tree inverse dynamics (constraints disabled) gives M qacc + bias; it must equal the
        slide forces plus the loop-closure forces J_eq^T lambda. Solved as one 24x24 system.
        Returns the forces and the solve's relative residual.
        """
        m, d = self.model, self.data
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        d.qacc[:] = qacc
        mujoco.mj_forward(m, d)                       # constraint Jacobian at this state
        eq_rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        jac_eq = d.efc_J.reshape(d.nefc, m.nv)[eq_rows].copy()
        saved = m.opt.disableflags
        m.opt.disableflags = saved | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
        d.qacc[:] = qacc
        mujoco.mj_inverse(m, d)
        tree = d.qfrc_inverse.copy()
        m.opt.disableflags = saved
        system = np.zeros((m.nv, 6 + jac_eq.shape[0]))
        system[self.slide_dof, np.arange(6)] = 1.0
        system[:, 6:] = jac_eq.T
        solution, *_ = np.linalg.lstsq(system, tree, rcond=None)
        residual = np.linalg.norm(system @ solution - tree) / max(np.linalg.norm(tree), 1e-12)
        return solution[:6], float(residual)


def hinge_angles(frame: np.ndarray, first_axis: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """The universal joint's two hinge angles that point a leg (home link `frame`, first hinge
    `first_axis` in the base frame) along the unit `direction` (base frame)."""
    n = frame.T @ first_axis
    target = frame.T @ direction
    # Rot(n, th1) Rot(y, th2) e_z = target; rotating about n keeps the component along n, so
    # th2 comes first, then th1 turns v = Rot(y, th2) e_z onto target
    th2 = _solve_second_hinge(n, target)
    v = np.array([np.sin(th2), 0.0, np.cos(th2)])
    vp = v - (n @ v) * n
    tp = target - (n @ target) * n
    return float(np.arctan2(n @ np.cross(vp, tp), vp @ tp)), th2


def vertical_hinges(frame: np.ndarray, first_axis: np.ndarray) -> tuple[float, float]:
    """The hinge angles of the leg standing vertical: the centre of the joint's cone."""
    return hinge_angles(frame, first_axis, np.array([0.0, 0.0, 1.0]))


def _solve_second_hinge(n: np.ndarray, target: np.ndarray) -> float:
    """th2 in [-pi/2, pi/2] with n_x sin th2 + n_z cos th2 = n . target."""
    amplitude = np.hypot(n[0], n[2])
    phase = np.arctan2(n[2], n[0])                  # n_x sin + n_z cos = A sin(th2 + phase)
    value = np.arcsin(np.clip((n @ target) / amplitude, -1.0, 1.0))
    candidates = np.array([value - phase, np.pi - value - phase])
    candidates = (candidates + np.pi) % (2 * np.pi) - np.pi
    return float(candidates[np.argmin(np.abs(candidates))])
