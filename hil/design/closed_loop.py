"""The hexapod's closed loop, linearised: the emulator's plant under the controller's own code.

The design basis of the computed-torque gains and the prediction the kick test is held to:

- plant: `modes.modal_model` (the emulator's equations linearised at a pose held at rest:
  mechanism, chambers, spool lag) with a wrench w on the platform at its centre of mass as a
  second input, x' = A x + B u + B_w w; discretised exactly over one period with the command
  held (zero-order hold);
- the bus's timing: the command computed from SYNC k's samples is applied from SYNC k+1;
- sensors: the encoders' strokes q and the load cells' rod forces
  F = A_p (p_A - alpha p_B) - sigma2 q' - m_rod q'' (the rod between piston and load cell);
- controller: the real `Controller` holding the pose, linearised by central differences of
  its `update` in its dynamic state (the legs' Kalman filters, the PID's integral, the
  twist's low-pass) and in its measurements: no second implementation of the control law.

The closed loop's eigenvalues z are mapped to s = ln(z) / T: frequency |s| / 2 pi, damping
ratio -Re s / |s|.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import cont2discrete

from firmware_py.config import ControllerConfig, load_config
from firmware_py.controller import Controller
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.computed_torque import STIFF_COUNT
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from hil.design.modes import AXES, ModalModel, blocks, modal_model
from physics.constants import GRAVITY_M_S2
from plant_emulator.params import EmulatorConfig
from protocol.enums import State, ValveState

PERIOD_S = 0.002
CONVERGE_CYCLES = 400                # the Kalman filters settle (their gain: the linearisation's)
# central-difference steps: the legs' Kalman states (m, m/s, m/s^2), the integral (m s), the
# twist filter's output and its rate, the encoders (m) and the load cells (N)
KALMAN_STEPS = (1e-5, 1e-4, 1e-3)
INTEGRAL_STEP = 1e-6
FILTER_STEPS = (1e-5, 1e-3)
POSITION_STEP = 1e-5
FORCE_STEP = 1e-2
# what the design model leaves to the plant: the monitors judge a real rig, not this model
# and its direct kinematics solved to far below the differences' steps
QUIET = {"residuals": {"enabled": False, "load_cell_noise_n": 0.0, "spool_check": False},
         "kinematics": {"dk_tolerance_um": 0.001}}


def controller_config(overrides: dict | None = None, payload_kg: float = 0.0) -> ControllerConfig:
    """The packaged controller config with `overrides` (sections of thesis-unit keys), the
    payload declared, its monitors quiet (they would judge this model's idealised signals)."""
    merged = {section: dict(values) for section, values in (overrides or {}).items()}
    for section, values in QUIET.items():
        merged.setdefault(section, {}).update(values)
    merged.setdefault("hexapod", {})["payload_kg"] = payload_kg
    return load_config(overrides=merged)


@dataclass
class Plant:
    """One period of the linearised plant: x+ = ad x + bd u + bw w; y = c x = (q, F)."""
    model: ModalModel
    ad: np.ndarray
    bd: np.ndarray
    bw: np.ndarray
    c: np.ndarray


def plant_of(cfg: EmulatorConfig, model: ModalModel, rod_mass_kg: float, period_s: float = PERIOD_S) -> Plant:
    n = model.jacobian.shape[0]
    Q, QD, PA, PB, _ = blocks(n)
    a = model.a
    bw = np.zeros((a.shape[0], 6))
    bw[QD] = np.linalg.solve(model.joint_inertia_kg, np.linalg.inv(model.jacobian).T)
    c = np.zeros((2 * n, a.shape[0]))
    c[:n, Q] = np.eye(n)
    c[n:, PA] = cfg.area_a_m2 * np.eye(n)
    c[n:, PB] = -cfg.area_a_m2 * cfg.alpha * np.eye(n)
    c[n:, QD] -= model.friction_slope_ns_m * np.eye(n)
    c[n:] -= rod_mass_kg * a[QD]
    inputs = np.hstack([model.b, bw])              # the valve commands and the wrench, held
    ad, bd, *_ = cont2discrete((a, inputs, c, np.zeros((c.shape[0], inputs.shape[1]))), period_s, method="zoh")
    return Plant(model, ad, bd[:, :n], bd[:, n:], c)


def _state_steps(ctl: Controller) -> np.ndarray:
    """The central differences' step of each of `Controller.dynamic_state`'s entries."""
    n = ctl.status.n_legs
    return np.concatenate([np.tile(KALMAN_STEPS, n), np.full(6 + STIFF_COUNT, INTEGRAL_STEP),
                           np.tile(FILTER_STEPS, 12), np.full(n, POSITION_STEP)])


def _read(views) -> np.ndarray:
    return np.concatenate([v.ravel() for v in views])


def _write(views, vector) -> None:
    k = 0
    for v in views:
        size = v.size
        v[...] = vector[k:k + size].reshape(v.shape)
        k += size


@dataclass
class ControllerLinearisation:
    """s+ = a s + b y, c = cs s + dy y (c the spool command, fraction of full input)."""
    a: np.ndarray
    b: np.ndarray
    cs: np.ndarray
    dy: np.ndarray
    spool_offset: np.ndarray


def _settled(cfg: ControllerConfig, model: ModalModel, forces_n, controller: str, period_s: float):
    """The controller holding the pose of `model` with its load cells at `forces_n`, settled
    (its Kalman filters' gain: the linearisation's); returned with its measurements."""
    ctl = Controller(cfg, "hexapod", period_s, CONTROLLER_NAMES[controller])
    meas, cmd = ctl.new_interfaces()
    meas.report_legs(model.strokes_m, forces_n, ValveState.ACTIVE)
    ctl.update(meas, cmd)
    ctl.activated(True)
    for _ in range(CONVERGE_CYCLES):
        ctl.update(meas, cmd)
    status = ctl.status
    if status.state is not State.READY:
        raise RuntimeError(f"the controller did not hold the pose ({status.state.name}, {status.fault.name})")
    return ctl, meas, cmd


def linearise_controller(cfg: ControllerConfig, model: ModalModel, forces_n, controller: str = "computed-torque",
                         period_s: float = PERIOD_S) -> ControllerLinearisation:
    """The controller settled on the operating point of `model` (`_settled`), then
    differentiated: central differences of one update, each from the settled state put back."""
    ctl, meas, cmd = _settled(cfg, model, forces_n, controller, period_s)
    settled = ctl.checkpoint()
    views = ctl.dynamic_state()
    s0 = _read(views)
    y0 = np.concatenate([meas.position_m, meas.force_n])
    n_legs = ctl.status.n_legs

    def step(s, y):
        settled.restore()
        meas.report_legs(y[:n_legs], y[n_legs:], ValveState.ACTIVE)
        _write(views, s)
        ctl.update(meas, cmd)
        return _read(views), cmd.spool.copy()

    ns, ny = s0.size, y0.size
    a, b = np.empty((ns, ns)), np.empty((ns, ny))
    cs, dy = np.empty((n_legs, ns)), np.empty((n_legs, ny))
    for j, h in enumerate(_state_steps(ctl)):
        plus, minus = step(s0 + h * np.eye(ns)[j], y0), step(s0 - h * np.eye(ns)[j], y0)
        a[:, j] = (plus[0] - minus[0]) / (2 * h)
        cs[:, j] = (plus[1] - minus[1]) / (2 * h)
    for j in range(ny):
        h = POSITION_STEP if j < n_legs else FORCE_STEP
        plus, minus = step(s0, y0 + h * np.eye(ny)[j]), step(s0, y0 - h * np.eye(ny)[j])
        b[:, j] = (plus[0] - minus[0]) / (2 * h)
        dy[:, j] = (plus[1] - minus[1]) / (2 * h)
    _, spool = step(s0, y0)
    settled.restore()
    return ControllerLinearisation(a, b, cs, dy, spool)


@dataclass
class ClosedMode:
    frequency_hz: float
    damping_ratio: float
    axis: str                          # the platform axis it moves most (rotations scaled by the radius)
    platform_share: float              # leg motion vs oil-column compression in the eigenvector (0..1)
    shape: np.ndarray                  # (6,) platform motion, unit peak

    def as_dict(self) -> dict:
        return {"frequency_hz": round(self.frequency_hz, 4), "damping_ratio": round(self.damping_ratio, 4),
                "axis": self.axis, "platform_share": round(self.platform_share, 4),
                "shape": [round(float(v), 4) for v in self.shape]}


@dataclass
class ClosedLoop:
    plant: Plant
    controller: ControllerLinearisation
    phi: np.ndarray                    # one period of the closed loop: z+ = phi z (+ gw w)
    gw: np.ndarray
    period_s: float
    radius_m: float

    def eigen(self) -> tuple[np.ndarray, np.ndarray]:
        return np.linalg.eig(self.phi)

    def spectral_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.phi))))

    def modes(self) -> list[ClosedMode]:
        """Every oscillating mode (one of each pair) and every real one, slowest first."""
        values, vectors = self.eigen()
        model = self.plant.model
        n = model.jacobian.shape[0]
        q, _, pa, pb, _ = blocks(n)
        inverse = np.linalg.inv(model.jacobian)
        area, alpha = self.plant.c[n, pa.start], -self.plant.c[n, pb.start] / self.plant.c[n, pa.start]
        out = []
        for k in range(len(values)):
            z = values[k]
            if z.imag < -1e-12 or abs(z) < 1e-12:
                continue
            s = np.log(z) / self.period_s
            magnitude = abs(s)
            vec = vectors[:, k]
            legs = vec[q]
            # the legs' motion against the oil columns' compression (as `modes.modes_of`)
            compression = np.linalg.norm(area * (vec[pa] - alpha * vec[pb]) / model.stiffness_n_m)
            size = np.linalg.norm(legs)
            share = float(size / (size + compression)) if size + compression > 0 else 0.0
            pose = inverse @ legs
            phase = pose[np.argmax(np.abs(pose))]
            pose = np.real(pose / (phase / abs(phase) if abs(phase) > 0 else 1.0))
            scaled = np.abs(pose) * np.r_[1.0, 1.0, 1.0, self.radius_m, self.radius_m, self.radius_m]
            peak = np.max(np.abs(pose)) or 1.0
            out.append(ClosedMode(magnitude / (2 * math.pi), float(-s.real / magnitude) if magnitude else 1.0,
                                  AXES[int(np.argmax(scaled))], share, pose / peak))
        return sorted(out, key=lambda m: m.frequency_hz)

    def push_response(self, axis: int, force: float, duration_s: float, seconds: float) -> np.ndarray:
        """The platform's pose (n, 6) after a push of `force` along base axis `axis` (0-2; a
        torque about 3-5) for `duration_s`, from rest."""
        n = self.plant.model.jacobian.shape[0]
        q = blocks(n)[0]
        inverse = np.linalg.inv(self.plant.model.jacobian)
        z = np.zeros(self.phi.shape[0])
        w = np.zeros(6)
        w[axis] = force
        out = np.empty((int(round(seconds / self.period_s)), 6))
        push_cycles = int(round(duration_s / self.period_s))
        for k in range(out.shape[0]):
            out[k] = inverse @ z[q]
            z = self.phi @ z + (self.gw @ w if k < push_cycles else 0.0)
        return out


def closed_loop(plant: Plant, lin: ControllerLinearisation, radius_m: float,
                period_s: float = PERIOD_S) -> ClosedLoop:
    """z = [x (plant), u (the command applied over this period), s (controller)]."""
    nx, n, ns = plant.ad.shape[0], plant.bd.shape[1], lin.a.shape[0]
    phi = np.zeros((nx + n + ns, nx + n + ns))
    phi[:nx, :nx] = plant.ad
    phi[:nx, nx:nx + n] = plant.bd
    phi[nx:nx + n, :nx] = lin.dy @ plant.c
    phi[nx:nx + n, nx + n:] = lin.cs
    phi[nx + n:, :nx] = lin.b @ plant.c
    phi[nx + n:, nx + n:] = lin.a
    gw = np.zeros((phi.shape[0], 6))
    gw[:nx] = plant.bw
    return ClosedLoop(plant, lin, phi, gw, period_s, radius_m)


def hexapod_closed_loop(emulator_cfg: EmulatorConfig, position_m, rpy_rad=(0.0, 0.0, 0.0), payload_kg: float = 0.0,
                        supply_pa: float | None = None, overrides: dict | None = None,
                        declared_payload_kg: float | None = None, model: ModalModel | None = None) -> ClosedLoop:
    """The closed loop holding a pose: the emulator's plant with `payload_kg`, the controller
    with the packaged config and `overrides`, told of `declared_payload_kg` (default: the
    payload). `model`: the plant's, made already."""
    model = model or modal_model(emulator_cfg, position_m, rpy_rad, payload_kg, supply_pa)
    cfg = controller_config(overrides, payload_kg if declared_payload_kg is None else declared_payload_kg)
    geometry = default_geometry()
    rod_mass = float(geometry.rod.mass_kg)
    plant = plant_of(emulator_cfg, model, rod_mass)
    # at rest the load cells read the slides' static forces less the rods' weight along the
    # legs (the Jacobian's translation columns: the legs' axes)
    forces = model.static_force_n - rod_mass * GRAVITY_M_S2 * model.jacobian[:, 2]
    lin = linearise_controller(cfg, model, forces)
    return closed_loop(plant, lin, float(np.linalg.norm(geometry.platform_anchor_m[0])))


def format_closed(modes: list[dict], min_share: float = 0.5) -> str:
    """The closed loop's platform modes (`ClosedMode.as_dict`) as a text table."""
    lines = ["closed loop (the packaged computed-torque controller, holding the pose):",
             "  f Hz      zeta   axis   legs share  shape x y z [m] roll pitch yaw [rad], unit peak"]
    for m in modes:
        if m["platform_share"] < min_share:
            continue
        lines.append(f"  {m['frequency_hz']:7.3f}  {m['damping_ratio']:6.3f}  {m['axis']:5s}  "
                     f"{m['platform_share']:10.2f}  {' '.join(f'{v:5.2f}' for v in m['shape'])}")
    return "\n".join(lines)
