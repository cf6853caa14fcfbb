"""The thesis's experiments in process (`hil.in_process`): how the design tools judge a
controller on the thesis's movements in seconds (HIL runs are the judge of record; in-process
figures land within a few % of them): the platform's movements of chapter 11.5, and the test
bench's sine and steps of chapter 7.6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.yaw_fusion import quat_yaw
from hil.experiments import Motion, segment_time
from hil.in_process import PERIOD_S, HostRefused, InProcessLoop
from plant_emulator.params import EmulatorConfig
from protocol.enums import Ack, State, WaypointFlag

SETTLE_S = 0.5                       # after the movement's last point, inside the error window


@dataclass
class Movement:
    """One movement's record, per cycle from its first waypoint: platform position and yaw
    (emulator truth) and the reference's position, every leg's valve command and load cell."""
    truth_m: np.ndarray
    reference_m: np.ndarray
    spool: np.ndarray
    force_n: np.ndarray
    yaw_rad: np.ndarray
    fault: str                                  # the fault that ended it, or "NONE"
    planned_s: float = math.nan                 # its waypoints' timing, from the first
    clock_lost_s: float = 0.0                   # what the online time scaling added to it (CTRL_CLOCK's RATE)

    @property
    def error_m(self) -> np.ndarray:
        return self.truth_m - self.reference_m

    @property
    def iae_m_s(self) -> np.ndarray:
        return np.sum(np.abs(self.error_m), axis=0) * PERIOD_S

    @property
    def max_error_m(self) -> np.ndarray:
        return np.max(np.abs(self.error_m), axis=0)

    @property
    def completed(self) -> bool:
        return self.fault == "NONE"

    @property
    def stretch(self) -> float:
        """How much longer than its timing the movement took: 1 when its clock never slowed."""
        return 1.0 + self.clock_lost_s / self.planned_s if self.planned_s > 0.0 else 1.0


def movement(loop: InProcessLoop, motion: Motion) -> Movement:
    """The movement's waypoints queued as `hil run pm-*` sends them, run to SETTLE_S after
    its last point or to a fault."""
    points = []
    for p, part in enumerate(motion.parts):
        for k, point in enumerate(part[1:]):
            flags = (WaypointFlag.START if k == 0 else 0) | (WaypointFlag.LAST if k == len(part) - 2 else 0)
            points.append((point, segment_time(motion, p, part[k], point), flags))
    record = {name: [] for name in ("truth", "reference", "spool", "force", "yaw")}
    status = loop.status
    lost = [0.0]

    def step() -> bool:
        loop.cycle()
        lost[0] += (1.0 - status.time_rate) * PERIOD_S
        position, quat = loop.rig.platform_pose()
        record["truth"].append(position.copy())
        record["yaw"].append(quat_yaw(quat))
        record["reference"].append(status.reference_pose[:3].copy())
        record["spool"].append(loop.cmd.spool.copy())
        record["force"].append(loop.meas.force_n.copy())
        return status.state is not State.FAULT

    for point, segment_s, flags in points:        # each acknowledged within a cycle, as over the bus
        if loop.send_waypoint(point, segment_s, motion.ta_s, flags) is not Ack.ACCEPTED:
            raise HostRefused(f"waypoint {np.round(np.asarray(point) * 1e3, 1)} mm refused")
    planned_s = sum(s for _, s, _ in points)
    done = 0                                      # the clock's lost time lengthens the run: it ends played
    while done * PERIOD_S < planned_s + lost[0] + SETTLE_S - 0.5 * PERIOD_S and step():
        done += 1
    return Movement(*(np.array(record[k]) for k in ("truth", "reference", "spool", "force", "yaw")),
                    status.fault.name if status.state is State.FAULT else "NONE", planned_s, lost[0])


def point_configs(payload_kg: float, supply_bar: float, computed_torque: dict | None = None,
                  config_path=None) -> tuple[ControllerConfig, EmulatorConfig]:
    """The controller's configuration as `hil run pm-*` makes it (MOVEMENT_OVERRIDES), the
    payload and supply declared and `computed_torque` keys over it, and the emulator's at that
    supply: an envelope point of the design tools."""
    from firmware_py.config import load_config
    from hil.experiments import MOVEMENT_OVERRIDES
    from plant_emulator.params import load_config as load_emulator_config
    overrides = {section: dict(values) for section, values in MOVEMENT_OVERRIDES.items()}
    overrides |= {"hexapod": {"payload_kg": payload_kg}, "hydraulic_model": {"supply_pressure_bar": supply_bar}}
    if computed_torque:
        overrides["computed_torque"] = dict(computed_torque)
    return (load_config(config_path, overrides=overrides),
            load_emulator_config(overrides={"actuator": {"supply_pressure_bar": supply_bar}}))


def run_movement(controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, motion: Motion,
                 controller: str = "computed-torque", payload_kg: float = 0.0, time_scale: float = 1.0,
                 seed: int = 7) -> Movement:
    """One of the thesis's movements from home, `time_scale` x its ta and tm."""
    loop = InProcessLoop(controller_cfg, emulator_cfg, controller, payload_kg, seed)
    loop.activate()
    return movement(loop, motion.scaled(time_scale))


def thesis_motions() -> dict[str, Motion]:
    from hil.experiments import MOTIONS
    geometry = default_geometry()
    return {name: motion(geometry) for name, motion in MOTIONS.items()}


def bench_sine(controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, load_kg: float, w_rad_s: float,
               seed: int = 7) -> tuple[float, str]:
    """sha-tracking's experiment on the test bench, in process: from the sine's bottom, one
    period of 150 - 125 cos(w t) mm as its waypoints; (the largest |y_r - y| over it [m],
    the fault that cut it or "NONE")."""
    from hil.experiments import SINE_AMPLITUDE_MM as AMPLITUDE_MM
    from hil.experiments import SINE_CENTRE_MM as CENTRE_MM
    from hil.experiments import SINE_POINTS_PER_PERIOD as POINTS_PER_PERIOD
    loop = InProcessLoop(controller_cfg, emulator_cfg, "computed-torque", load_kg, seed, rig="testbench")
    loop.activate(100)
    status = loop.status
    start = WaypointFlag.START | WaypointFlag.LAST
    loop.waypoint((0.0, 0.0, (CENTRE_MM - AMPLITUDE_MM) * 1e-3), 1.35, 0.1, int(start))
    loop.cycles(int(round(1.9 / PERIOD_S)))
    if loop.faulted:
        return 0.0, status.fault.name
    tm = 2e-3 * round(2 * math.pi / w_rad_s / POINTS_PER_PERIOD / 2e-3)
    for k in range(1, POINTS_PER_PERIOD + 1):
        y = CENTRE_MM - AMPLITUDE_MM * math.cos(2 * math.pi * k / POINTS_PER_PERIOD)
        loop.waypoint((0.0, 0.0, y * 1e-3), tm, round(tm / 2, 3), int(start) if k == POINTS_PER_PERIOD else 0)
    worst = 0.0
    for _ in range(int(round((tm * POINTS_PER_PERIOD + 0.3) / PERIOD_S))):
        loop.cycle()
        if loop.faulted:
            return worst, status.fault.name
        if status.moving:
            worst = max(worst, abs(float(status.reference_m[0] - loop.meas.position_m[0])))
    return worst, "NONE"


def bench_step(controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, load_kg: float, position_m: float,
               step_m: float = 0.01, hold_s: float = 1.2, seed: int = 7, controller: str = "computed-torque") -> dict:
    """sha-step's experiment at one position, in process: there, then a `step_m` square wave
    up, down, up; the last up-step's `hil.metrics.step_response` (or {"fault": ...})."""
    from hil.metrics import step_response
    loop = InProcessLoop(controller_cfg, emulator_cfg, controller, load_kg, seed, rig="testbench")
    loop.activate(100)
    flags = WaypointFlag.START | WaypointFlag.LAST
    loop.waypoint((0.0, 0.0, position_m), 2.0, 0.1, int(flags))
    cycles = int(round(hold_s / PERIOD_S))
    loop.cycles(int(round(3.0 / PERIOD_S)))
    for target in (position_m + step_m, position_m, position_m + step_m):
        if loop.faulted:
            return {"fault": loop.status.fault.name}
        y0 = float(np.mean(loop.meas.position_m))
        loop.waypoint((0.0, 0.0, target), hold_s, hold_s / 2, int(flags | WaypointFlag.STEP))
        y = []
        for _ in range(cycles):
            loop.cycle()
            y.append(float(loop.meas.position_m[0]))
    if loop.faulted:
        return {"fault": loop.status.fault.name}
    return step_response(np.arange(len(y)) * PERIOD_S, np.array(y), y0, step_m)


def linear_step(controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, mode: int, position_mm: float,
                load_kg: float, step_m: float = 0.010, seconds: float = 2.0):
    """The joint pipeline (`mode`: PI or ADAPTIVE) driving Table A.3's identified plant at a
    set point (`LinearRig`: no friction, no chambers) through the simulated rig's valve and
    sensors: settled at rest, then a step of its reference. (t, y [m], y0, the pipeline)."""
    from firmware_py.motion_control.joint_space import JointController
    from plant_emulator.linear_rig import LinearRig
    from plant_emulator.simulated_rig import SimulatedRig
    from protocol.interfaces import Measurements, ValveCommands
    rig = LinearRig.table_a3(emulator_cfg, position_mm, load_kg)
    sim = SimulatedRig(rig, emulator_cfg)
    meas, cmd = Measurements(1, 1), ValveCommands(1)
    cmd.active[:] = 1.0                      # the valve follows: HOLD, then ACTIVE at the next SYNC
    cfg = controller_cfg
    joint = JointController(cfg, 1, PERIOD_S, moving_mass_kg=cfg.actuator.moving_mass_kg,
                            mass_offset_kg=cfg.testbench.slide_mass_kg,
                            guide_friction=(cfg.testbench.guide_coulomb_n, cfg.testbench.guide_viscous_ns_m))
    joint.reset(position_mm * 1e-3)
    joint.set_mode(mode)
    yr, ar, g_axial, tau = np.full(1, position_mm * 1e-3), np.zeros(1), np.full(1, 9.81), np.zeros(1)

    def cycle():
        sim.read(meas)
        joint.update(meas.position_m, meas.fresh, meas.force_n, yr, ar, g_axial, tau, True)
        cmd.spool[0] = joint.u_v[0] / cfg.actuator.valve_full_scale_v
        sim.write(cmd)

    for _ in range(1500):                    # settle the estimators at rest first
        cycle()
    y0 = float(rig.stroke_m[0])
    yr[0] = y0 + step_m
    t, ys = [], []
    for k in range(int(seconds / PERIOD_S)):
        cycle()
        t.append(k * PERIOD_S)
        ys.append(float(rig.stroke_m[0]))
    return np.array(t), np.array(ys), y0, joint
