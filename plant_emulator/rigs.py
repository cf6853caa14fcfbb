"""The two rigs the emulator can be: the single-actuator test bench and the hexapod.

Both expose the same surface to the node layer: `n_legs`, `state` (n_legs x S_SIZE, the
actuator states of hydraulics.py), `command` (valve input per leg, fraction of full
input, written by the valve nodes), `jammed` (per-leg spool frozen), `seized` (per-leg rod
stuck mechanically: `set_rod_seized`), `ports_open` (per leg, 0 when the load-holding valves
between servo-valve and cylinder are closed: the node layer closes them whenever the valve
is not ACTIVE), `supply_pressure_pa` (the power unit's state, `physics.power_unit`),
`advance(period_s)` (integrate exactly that much physics), `rod_force_n` (what the load
cells measure), `set_load(kg)` and `unstable_periods` / `first_unstable_s` (advances after
which the physics had diverged: MuJoCo reset, or a state not finite).

- `TestbenchRig` (chapters 5-7): one vertical actuator lifting the 1.35 kg slide of a linear
  guide plus an external mass; guide friction eq. D.3 (default: eq. D.4, see emulator.toml);
  seal friction LuGre.
  One degree of freedom, integrated by our own numba kernel (semi-implicit velocity, exact
  LuGre bristles, implicit chambers), hard end stops.
- `HexapodRig`: six actuators driving the MuJoCo 6-UPS (`mechanism.Mechanism`). Per MuJoCo
  step the hydraulic force minus the bristle force goes to the slide motors and the
  friction's velocity slope to the slide's joint damping (MuJoCo's Euler integrates joint
  damping implicitly); after the step the bristles and chambers advance with the new leg
  velocities, in `hydraulic_substeps` sub-steps.

Both start at rest with each leg's chambers where its valve held them before the
load-holding valves closed (`hydraulics.resting_pressures`): at the valve's own level (the
return edges' wider underlap keeps it low), so opening the ports moves nothing.

The load cell sits on the rod between piston and load (chapter 8.2.3): it measures the
axial force the rod transmits to the load, positive when it pushes (compression).
"""

from __future__ import annotations

import math

import mujoco
import numba
import numpy as np

from physics import hydraulics as hy
from physics import power_unit
from physics.constants import GRAVITY_M_S2
from physics.lugre import force_split, z_step
from plant_emulator.mechanism import Mechanism
from plant_emulator.params import EmulatorConfig
from plant_emulator.rig_geometry import RigGeometry, read_rig_geometry

SUPPLY_LOSS_TIME_CONSTANT_S = 0.05    # supply pressure decay when the power unit is lost
NO_POWER_UNIT = np.zeros(0)           # the kernels hold the supply they are given
# MuJoCo's warnings that it reset a diverged simulation, or met a non-finite motor force
MUJOCO_DIVERGED = tuple(int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                         mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADCTRL))
SEIZED_FRICTION_N = 1e5               # LEG_JAM on the hexapod: dry friction of a seized slide,
SEIZED_SOLREF = (0.001, 1.0)          # as stiff as the solver allows at the 0.5 ms step
SEIZED_SOLIMP = (0.9999, 0.9999, 0.0001, 0.5, 2.0)


@numba.njit(cache=True)
def testbench_advance(st: np.ndarray, slide: np.ndarray, bolted: bool, command: float, jammed: bool, seized: bool,
                      ports: float, seal_leak: float, n: int, h: float, ps: float, hp: np.ndarray, fp: np.ndarray,
                      gp: np.ndarray, rod_mass: float, load_mass: float, pu: np.ndarray, out: np.ndarray) -> float:
    """n sub-steps of h of the test bench; out = [acceleration, seal friction, guide friction,
    1 where the slide rides on the rod]. `slide` = [y, v] of the guide's slide: bolted to the
    rod, it moves with it; unbolted (Appendix D's free falls), it rests on the rod's tip while
    the rod pushes it and falls on its own (weight, guide friction) when the rod leaves it.
    Returns the supply pressure after them (the power unit `pu`; empty: `ps` held)."""
    mass = rod_mass + load_mass
    stroke = hp[hy.HP_STROKE]
    y, v = st[hy.S_Y], st[hy.S_V]
    ys, vs = (y, v) if bolted else (slide[0], slide[1])
    accel = 0.0
    seal = 0.0
    guide = 0.0
    together = True
    decay = hy.spool_decay(h, hp)
    for _ in range(n):
        if not jammed:
            st[hy.S_SPOOL] = hy.spool_lag(st[hy.S_SPOOL], command, decay)
        drive = hy.piston_force(st[hy.S_PA], st[hy.S_PB], hp)            # eq. 4.15
        seal_z, seal_c = force_split(st[hy.S_Z], v, fp)                  # eq. 6.1-6.3
        guide_z, guide_c = force_split(st[hy.S_ZG], vs, gp)              # eq. D.3
        # each body alone: m dv/dt = F - m g, the friction's v-slope implicit
        v_rod = (rod_mass * v + h * (drive - seal_z - rod_mass * GRAVITY_M_S2)) / (rod_mass + h * seal_c)
        v_slide = (load_mass * vs + h * (-guide_z - load_mass * GRAVITY_M_S2)) / (load_mass + h * guide_c)
        together = bolted or (ys <= y and v_slide <= v_rod)             # bolted, or the rod pushes the slide
        if together:
            v_rod = (rod_mass * v + load_mass * vs + h * (drive - seal_z - guide_z - mass * GRAVITY_M_S2)) / (
                mass + h * (seal_c + guide_c))
        if seized:                                                       # the rod does not move
            v_rod = 0.0
        y_new = y + h * v_rod
        if y_new <= 0.0:                                                 # end stops: inelastic
            y_new = 0.0
            v_rod = max(v_rod, 0.0)
        elif y_new >= stroke:
            y_new = stroke
            v_rod = min(v_rod, 0.0)
        if together:
            ys_new, v_slide = y_new, v_rod
        else:
            ys_new = ys + h * v_slide
            if ys_new <= y_new:                                          # it lands on the rod: inelastic
                v_rod = v_slide = (rod_mass * v_rod + load_mass * v_slide) / mass
                ys_new = y_new
                together = True
        seal = seal_z + seal_c * v_rod
        guide = guide_z + guide_c * v_slide
        st[hy.S_Z] = z_step(st[hy.S_Z], v_rod, h, fp)
        st[hy.S_ZG] = z_step(st[hy.S_ZG], v_slide, h, gp)
        hy.chamber_step(st, y_new, v_rod, ps, h, hp, ports, seal_leak)
        accel = (v_rod - v) / h
        y, v, ys, vs = y_new, v_rod, ys_new, v_slide
    st[hy.S_Y], st[hy.S_V] = y, v
    slide[0], slide[1] = ys, vs
    out[0], out[1], out[2], out[3] = accel, seal, guide, 1.0 if together else 0.0
    if pu.shape[0]:                    # one leg far inside the pump's flow: the supply once a period
        drawn, slope = hy.supply_flow(st[hy.S_SPOOL], st[hy.S_PA], st[hy.S_PB], ps, hp, ports)
        ps = power_unit.supply_step(ps, drawn, slope, n * h, pu)
    return ps


@numba.njit(cache=True)
def legs_drive_mujoco(st: np.ndarray, velocity: np.ndarray, hp: np.ndarray, fp: np.ndarray, slide_dof: np.ndarray,
                      ctrl: np.ndarray, dof_damping: np.ndarray) -> None:
    """Per leg: hydraulic force minus the bristle force (explicit) into the slide's motor, the
    friction's velocity slope into its joint damping."""
    for i in range(st.shape[0]):
        z_force, slope = force_split(st[i, hy.S_Z], velocity[i], fp)
        ctrl[i] = hy.piston_force(st[i, hy.S_PA], st[i, hy.S_PB], hp) - z_force
        dof_damping[slide_dof[i]] = slope


@numba.njit(cache=True)
def legs_read_mujoco(qpos: np.ndarray, qvel: np.ndarray, slide_qpos: np.ndarray, slide_dof: np.ndarray,
                     stroke_offset: np.ndarray, stroke: np.ndarray, velocity: np.ndarray) -> None:
    """Each leg's stroke and velocity from MuJoCo's slide joints."""
    for i in range(stroke.shape[0]):
        stroke[i] = qpos[slide_qpos[i]] + stroke_offset[i]
        velocity[i] = qvel[slide_dof[i]]


@numba.njit(cache=True)
def legs_hydraulics(st: np.ndarray, stroke: np.ndarray, velocity: np.ndarray, command: np.ndarray,
                    jammed: np.ndarray, ports: np.ndarray, seal_leak: np.ndarray, n: int, h: float, ps: float,
                    hp: np.ndarray, fp: np.ndarray, pu: np.ndarray) -> float:
    """Advance spool, bristles and chambers of every leg by n x h at the given leg motion, and
    the supply they share (the power unit `pu`; empty: `ps` held). Returns the supply."""
    for i in range(st.shape[0]):
        st[i, hy.S_Y] = stroke[i]
        st[i, hy.S_V] = velocity[i]
    decay = hy.spool_decay(h, hp)
    for _ in range(n):
        drawn = slope = 0.0
        for i in range(st.shape[0]):
            if not jammed[i]:
                st[i, hy.S_SPOOL] = hy.spool_lag(st[i, hy.S_SPOOL], command[i], decay)
            st[i, hy.S_Z] = z_step(st[i, hy.S_Z], velocity[i], h, fp)
            hy.chamber_step(st[i], stroke[i], velocity[i], ps, h, hp, ports[i], seal_leak[i])
            flow, flow_slope = hy.supply_flow(st[i, hy.S_SPOOL], st[i, hy.S_PA], st[i, hy.S_PB], ps, hp, ports[i])
            drawn += flow
            slope += flow_slope
        if pu.shape[0]:
            ps = power_unit.supply_step(ps, drawn, slope, h, pu)
    return ps


@numba.njit(cache=True)
def connect_axial_forces(efc_type: np.ndarray, efc_force: np.ndarray, equality: int, site_xpos: np.ndarray,
                         platform_site: np.ndarray, xpos: np.ndarray, cylinder_body: np.ndarray,
                         out: np.ndarray) -> None:
    """Each leg's connect constraint (its three equality rows, in leg order) along the leg's axis,
    cylinder -> rod end: -f . u, the rod's push on the platform."""
    leg, row = 0, 0
    for k in range(efc_type.shape[0]):
        if efc_type[k] != equality:
            continue
        if row == 0:
            axis = site_xpos[platform_site[leg]] - xpos[cylinder_body[leg]]
            length = math.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
            out[leg] = 0.0
        out[leg] -= efc_force[k] * (axis[row] / length)
        row += 1
        if row == 3:
            leg, row = leg + 1, 0


class _RigBase:
    n_legs: int

    def __init__(self, cfg: EmulatorConfig):
        self.cfg = cfg
        self.state = np.zeros((self.n_legs, hy.S_SIZE))
        self.command = np.zeros(self.n_legs)
        self.jammed = np.zeros(self.n_legs, dtype=bool)
        self.seized = np.zeros(self.n_legs, dtype=bool)
        self.ports_open = np.ones(self.n_legs)     # 0: the load-holding valves block the chambers
        self.seal_leak = np.full(self.n_legs, cfg.hp[hy.HP_SEAL_LEAK])    # each piston seal's leakage
        self.rod_force_n = np.zeros(self.n_legs)
        self.supply_pressure_pa = cfg.actuator.supply_pressure_pa
        self.supply_fraction = 1.0
        self.time_s = 0.0
        self.unstable_periods = 0                  # advances after which the physics was not finite
        self.first_unstable_s: float | None = None
        self.joint_limit_periods = 0               # advances that ended with a joint on its stop (hexapod)
        self.first_joint_limit_s: float | None = None

    def _note_stability(self, unstable: bool) -> None:
        """Count an advance whose physics diverged (what follows it is not physics)."""
        if unstable or not np.isfinite(self.state).all():
            self.unstable_periods += 1
            if self.first_unstable_s is None:
                self.first_unstable_s = self.time_s

    def _supply_for(self, period_s: float) -> tuple[float, np.ndarray]:
        """(the supply at the period's start, the power unit that runs it through the period);
        a failing unit (a supply fault) falls to its share with its own time constant instead."""
        tank = self.cfg.hp[hy.HP_TANK]
        if self.supply_fraction >= 1.0:
            return self.supply_pressure_pa, self.cfg.pu
        # the power unit delivers part of its pressure (0: it stopped, to the tank's)
        target = tank + self.supply_fraction * (self.cfg.actuator.supply_pressure_pa - tank)
        self.supply_pressure_pa = target + (self.supply_pressure_pa - target) * math.exp(
            -period_s / SUPPLY_LOSS_TIME_CONSTANT_S)
        return self.supply_pressure_pa, NO_POWER_UNIT

    def set_rod_seized(self, leg: int, seized: bool) -> None:
        self.seized[leg] = seized

    def set_seal_leak(self, leg: int, factor: float) -> None:
        """A worn piston seal of `leg` passing `factor` times the calibrated A <-> B leakage
        (0: sound again); unlike that leakage it is not cut by the load-holding valves."""
        hp = self.cfg.hp
        self.seal_leak[leg] = factor * hp[hy.HP_LEAK] if factor > 0.0 else hp[hy.HP_SEAL_LEAK]

    def set_supply_fraction(self, fraction: float) -> None:
        """The power unit's pressure above the tank's, as a fraction of its nominal (0: it
        stopped); the supply falls to it with the supply-loss time constant, 1 restores it at once."""
        self.supply_fraction = fraction
        if fraction >= 1.0:
            self.supply_pressure_pa = self.cfg.actuator.supply_pressure_pa

    @property
    def stroke_m(self) -> np.ndarray:
        return self.state[:, hy.S_Y]


class TestbenchRig(_RigBase):
    """One actuator lifting the slide of a vertical linear guide plus an external mass."""

    n_legs = 1
    name = "testbench"
    __test__ = False            # not a pytest class despite the name

    def __init__(self, cfg: EmulatorConfig, load_kg: float | None = None, start_mm: float = 150.0):
        super().__init__(cfg)
        self.out = np.zeros(4)
        self.slide = np.zeros(2)              # the guide's slide [y, v] while unbolted from the rod
        self.bolted = True
        self.set_load(cfg.testbench.load_kg if load_kg is None else load_kg)
        self.state[0, hy.S_Y] = min(max(start_mm * 1e-3, 0.0), cfg.stroke_m)
        hold = (cfg.actuator.piston_rod_mass_kg + self.load_mass_kg) * GRAVITY_M_S2
        self.state[0, hy.S_PA], self.state[0, hy.S_PB] = hy.resting_pressures(float(self.state[0, hy.S_Y]), hold,
                                                                              cfg.actuator.supply_pressure_pa, cfg.hp)
        self.rod_force_n[0] = self.load_mass_kg * GRAVITY_M_S2          # at rest

    def set_load(self, load_kg: float) -> None:
        self.load_kg = float(load_kg)
        self.load_mass_kg = self.cfg.guide.slide_mass_kg + self.load_kg
        self.guide_friction = self.cfg.guide.lugre_vector(self.load_kg)

    def unbolt_slide(self) -> None:
        """Appendix D: the slide (with its mass) unbolted from the rod; it rests on the rod's
        tip and falls on its guide when the rod drops away."""
        if self.bolted:
            self.slide[0], self.slide[1] = self.state[0, hy.S_Y], self.state[0, hy.S_V]
            self.bolted = False

    def bolt_slide(self) -> bool:
        """Bolt the slide to the rod again: only where it rests on the rod's tip."""
        if not self.bolted and self.out[3] > 0.0:
            self.bolted = True
        return self.bolted

    @property
    def gap_m(self) -> float:
        """The slide's height above the rod's tip (0 while bolted or riding on it)."""
        return 0.0 if self.bolted else float(self.slide[0] - self.state[0, hy.S_Y])

    @property
    def stroke_m(self) -> np.ndarray:
        """What the guide's encoder reads: the slide's position (the rod's while bolted)."""
        return self.state[:, hy.S_Y] if self.bolted else self.slide[0:1]

    def advance(self, period_s: float) -> None:
        n = max(1, round(period_s / self.cfg.testbench.substep_s))
        ps, unit = self._supply_for(period_s)
        self.supply_pressure_pa = testbench_advance(
            self.state[0], self.slide, self.bolted, float(self.command[0]), bool(self.jammed[0]),
            bool(self.seized[0]), float(self.ports_open[0]), float(self.seal_leak[0]), n, period_s / n, ps,
            self.cfg.hp, self.cfg.friction.vector, self.guide_friction, self.cfg.actuator.piston_rod_mass_kg,
            self.load_mass_kg, unit, self.out)
        # the rod carries the load's weight, inertia and guide friction (nothing once the slide left it)
        riding = self.out[3] > 0.0
        self.rod_force_n[0] = self.load_mass_kg * (self.out[0] + GRAVITY_M_S2) + self.out[2] if riding else 0.0
        self.time_s += period_s
        self._note_stability(False)

    def warm_up(self) -> None:
        """Load the compiled kernels now: their first call costs 0.2-0.25 s (numba's cache),
        which in the first SYNC made the nodes miss ~45 realtime cycles. Scratch copies only."""
        testbench_advance(self.state[0].copy(), self.slide.copy(), True, 0.0, False, False, 1.0,
                          float(self.seal_leak[0]), 1, self.cfg.testbench.substep_s,
                          self.cfg.actuator.supply_pressure_pa,
                          self.cfg.hp, self.cfg.friction.vector, self.guide_friction,
                          self.cfg.actuator.piston_rod_mass_kg, self.load_mass_kg, self.cfg.pu, np.zeros(4))

    @property
    def acceleration_m_s2(self) -> float:
        return float(self.out[0])

    @property
    def seal_friction_n(self) -> float:
        return float(self.out[1])


class HexapodRig(_RigBase):
    """Six actuators on the MuJoCo 6-UPS, starting at rest at the home pose."""

    n_legs = 6
    name = "hexapod"

    def __init__(self, cfg: EmulatorConfig, geometry: RigGeometry | None = None):
        super().__init__(cfg)
        self.geometry = geometry or read_rig_geometry()
        self.mechanism = Mechanism(self.geometry, timestep_s=cfg.hexapod.mujoco_timestep_s, joint_limits=True)
        mech, model = self.mechanism, self.mechanism.model
        self.home_length_m = np.array([leg.length_m for leg in mech.legs_home])
        self._cylinder_body = model.body_parentid[model.site_bodyid[mech.rod_site]]
        self._platform_mass0 = float(model.body_mass[mech.platform_body])
        self._solref_default = model.dof_solref[mech.slide_dof].copy()
        self._solimp_default = model.dof_solimp[mech.slide_dof].copy()
        self.set_load(cfg.hexapod.payload_kg)
        self._wrench = np.zeros(6)                # an external push on the platform (EMU_KICK)
        self._wrench_applied = False              # MuJoCo holds a push until it is cleared
        self._kick_left_s = 0.0
        self._stroke_offset = self.home_length_m - self.geometry.leg_min_m
        self._velocity = np.zeros(6)
        self._stroke = np.zeros(6)
        self._read_legs()
        self.state[:, hy.S_Y] = self._stroke
        static, _ = mech.inverse_forces(mech.data.qpos.copy(), np.zeros(model.nv), np.zeros(model.nv))
        for i in range(6):
            self.state[i, hy.S_PA], self.state[i, hy.S_PB] = hy.resting_pressures(
                float(self._stroke[i]), float(static[i]), cfg.actuator.supply_pressure_pa, cfg.hp)
        mech.set_pose(self.geometry.home_position_m, self.geometry.home_quaternion)
        self._measure_rod_forces()

    def set_load(self, load_kg: float) -> None:
        """A payload at the platform's centre of mass (a point mass there adds no inertia about it)."""
        self.load_kg = float(load_kg)
        self.mechanism.model.body_mass[self.mechanism.platform_body] = self._platform_mass0 + self.load_kg

    def set_rod_seized(self, leg: int, seized: bool) -> None:
        """A seized rod: MuJoCo's dry friction on the slide, far above any hydraulic force
        (113 mm2 x 100 bar ~ 1.1 kN), with a stiff constraint (the default soft one lets the
        rod slide 150 mm in 0.5 s at 30 % valve input; this one 0.03 mm)."""
        super().set_rod_seized(leg, seized)
        model = self.mechanism.model
        dof = self.mechanism.slide_dof[leg]
        model.dof_frictionloss[dof] = SEIZED_FRICTION_N if seized else 0.0
        model.dof_solref[dof] = SEIZED_SOLREF if seized else self._solref_default[leg]
        model.dof_solimp[dof] = SEIZED_SOLIMP if seized else self._solimp_default[leg]

    def kick(self, axis: int, value: float, duration_s: float) -> None:
        """Push the platform for `duration_s`, from the next step on: a force [N] along base
        axis 0-2 or a torque [N m] about 3-5, at its centre of mass (MuJoCo's xfrc_applied)."""
        self._wrench[:] = 0.0
        self._wrench[axis] = value
        self._kick_left_s = duration_s

    def _read_legs(self) -> None:
        mech = self.mechanism
        legs_read_mujoco(mech.data.qpos, mech.data.qvel, mech.slide_qpos, mech.slide_dof, self._stroke_offset,
                         self._stroke, self._velocity)

    def advance(self, period_s: float) -> None:
        mech, cfg = self.mechanism, self.cfg
        model, data = mech.model, mech.data
        steps = max(1, round(period_s / model.opt.timestep))
        ps, unit = self._supply_for(period_s)
        sub = cfg.hexapod.hydraulic_substeps
        h = model.opt.timestep / sub
        for _ in range(steps):
            if self._kick_left_s > 0.0 or self._wrench_applied:
                data.xfrc_applied[mech.platform_body] = self._wrench
                self._wrench_applied = self._kick_left_s > 0.0
                self._kick_left_s -= model.opt.timestep
                if self._kick_left_s <= 0.0:
                    self._wrench[:] = 0.0         # the next step runs without it
            # one kernel call each side of the step (the Python between them cost as much as MuJoCo)
            legs_drive_mujoco(self.state, self._velocity, cfg.hp, cfg.friction.vector, mech.slide_dof, data.ctrl,
                              model.dof_damping)
            mujoco.mj_step(model, data)
            self._read_legs()
            ps = legs_hydraulics(self.state, self._stroke, self._velocity, self.command, self.jammed,
                                 self.ports_open, self.seal_leak, sub, h, ps, cfg.hp, cfg.friction.vector, unit)
        self.supply_pressure_pa = ps
        self._measure_rod_forces()
        self.time_s += steps * model.opt.timestep
        # MuJoCo resets its state where it diverges (and warns on stderr): count it, then clear
        diverged = False
        for kind in MUJOCO_DIVERGED:
            if data.warning[kind].number:
                diverged, data.warning[kind].number = True, 0
        self._note_stability(diverged)
        if mech.at_joint_limit():
            self.joint_limit_periods += 1
            if self.first_joint_limit_s is None:
                self.first_joint_limit_s = self.time_s

    def warm_up(self) -> None:
        """As TestbenchRig.warm_up: the kernels loaded on scratch copies, the rig untouched."""
        cfg, state = self.cfg, self.state.copy()
        mech = self.mechanism
        legs_drive_mujoco(state, self._velocity, cfg.hp, cfg.friction.vector, mech.slide_dof, np.zeros(6),
                          np.zeros(mech.model.nv))
        legs_read_mujoco(mech.data.qpos, mech.data.qvel, mech.slide_qpos, mech.slide_dof, self._stroke_offset,
                         np.zeros(6), np.zeros(6))
        legs_hydraulics(state, self._stroke.copy(), self._velocity.copy(), np.zeros(6), self.jammed,
                        self.ports_open, self.seal_leak, 1,
                        cfg.testbench.substep_s, cfg.actuator.supply_pressure_pa, cfg.hp, cfg.friction.vector,
                        cfg.pu)

    def _measure_rod_forces(self) -> None:
        """Axial force of each connect constraint (rod end -> platform), compression positive.

        A connect's three rows carry the force f on the rod end in world axes (the platform
        gets -f); the rod pushes the platform along the leg axis u by -f . u.
        """
        mech, data = self.mechanism, self.mechanism.data
        connect_axial_forces(data.efc_type, data.efc_force, int(mujoco.mjtConstraint.mjCNSTR_EQUALITY),
                             data.site_xpos, mech.platform_site, data.xpos, self._cylinder_body, self.rod_force_n)

    def platform_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Ground truth: platform position [m] and quaternion (w, x, y, z)."""
        pos, quat, *_ = self.mechanism.platform_state()
        return pos, quat

    def platform_body_rate(self) -> np.ndarray:
        """Angular velocity in the platform frame (what a strapdown IMU measures) [rad/s]."""
        mech = self.mechanism
        return mech.data.qvel[mech.free_dof + 3:mech.free_dof + 6].copy()

    def closure_error_m(self) -> float:
        return self.mechanism.closure_error_m()


RIGS = {"testbench": TestbenchRig, "hexapod": HexapodRig}


def make_rig(name: str, cfg: EmulatorConfig, load_kg: float | None = None):
    if name == "testbench":
        return TestbenchRig(cfg, load_kg)
    rig = HexapodRig(cfg)
    if load_kg is not None:
        rig.set_load(load_kg)
    return rig
