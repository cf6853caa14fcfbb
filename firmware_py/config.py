"""The controller's configuration: `data/controller.toml` (thesis units) plus an optional
user file with the same sections and keys, one frozen section per TOML table, each key
declared once with its range and converted to SI at load (`program.sections`). Keys the
emulator reads too are declared once in `physics` and `protocol`. Errors are one line
naming the file, the key, the value and the allowed range (`ConfigError`; the CLI exits 2).

Each component takes its own section: the loop [timing], the supervisor [supervisor], the
waypoint queue [waypoints], the limit monitors [limits], and so on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np

from physics import hydraulics as hy
from physics import power_unit as pu
from physics.actuator import (
    ENCODER_RESOLUTION,
    GUIDE_COULOMB,
    GUIDE_VISCOUS,
    LOAD_CELL_NOISE,
    PAYLOAD,
    PRESSURE_NOISE,
    SLIDE_MASS,
    VALVE_FULL_SCALE,
    CylinderSection,
)
from physics.constants import BAR, MM, MS, US
from physics.lugre import LugreSection
from program.errors import UserInputError
from program.realtime import CPU_LATENCY, REALTIME_PRIORITY
from program.sections import STR, ConfigFile, Section, flag, frozen, key, load_file, numbers, table
from protocol.devices import IMU_EDS, LEG_EDS, check_files
from protocol.enums import SYNC_SOURCES
from protocol.nodes import HEARTBEAT

PCT = 100.0                         # a percentage is divided by it
SCHEDULE_LOADS = ("0kg", "3kg", "6kg")


class ConfigError(UserInputError):
    """A configuration value the controller cannot use."""


def default_config_path() -> Path:
    return Path(str(resources.files("firmware_py").joinpath("data/controller.toml")))


@frozen
class Timing(Section):
    """The loop on the bus (runtime/loop.py, daemon.py)."""
    sync_window_fraction: float = key("sync_window_fraction", 0.1, 0.95)
    spin_s: float = key("spin_us", 0.0, 5000.0, si=US)
    commit_room_s: float = key("commit_room_us", 0.0, 100000.0, si=US)
    lockstep_timeout_s: float = key("lockstep_timeout_ms", 1.0, 10000.0, si=MS)
    activation_timeout_s: float = key("activation_timeout_s", 0.1, 600.0)
    hold_cycles: int = key("hold_cycles", 1, 10000)
    shutdown_hold_cycles: int = key("shutdown_hold_cycles", 1, 10000)
    shutdown_disable_cycles: int = key("shutdown_disable_cycles", 1, 10000)
    heartbeat_s: float = key(HEARTBEAT)
    heartbeat_timeout_s: float = key("heartbeat_timeout_ms", 10.0, 60000.0, si=MS)
    realtime_priority: int = key(REALTIME_PRIORITY)
    cpu: int = key("cpu", -1, 1023)
    cpu_latency_us: int = key(CPU_LATENCY)
    stall_fault_periods: float = key("stall_fault_periods", 1.0, 10000.0)
    sync_source: str = key("sync_source", kind=STR)

    def validate(self, where, error) -> None:
        if self.sync_source not in SYNC_SOURCES:
            raise error(f"{where}.sync_source = {self.sync_source!r}: must be one of {', '.join(SYNC_SOURCES)}")


@frozen
class Devices(Section):
    """Who must answer at each node id (runtime/identify.py): each kind's EDS, read back by SDO."""
    leg_eds: str = key(LEG_EDS)
    imu_eds: str = key(IMU_EDS)
    sdo_timeout_s: float = key("sdo_timeout_ms", 1.0, 10000.0, si=MS)

    def validate(self, where: str, error: type[UserInputError]) -> None:
        check_files((self.leg_eds, self.imu_eds), where, error)


@frozen
class Actuator(CylinderSection):
    """Each leg's cylinder, valve input and encoder (chapter 4.2)."""
    moving_mass_kg: float = key("moving_mass_kg", 0.0, 50.0)
    valve_full_scale_v: float = key(VALVE_FULL_SCALE)
    encoder_resolution_m: float = key(ENCODER_RESOLUTION)


@frozen
class Testbench(Section):
    """The single-actuator rig: its slide, its positions, its own motion window."""
    slide_mass_kg: float = key(SLIDE_MASS)
    home_m: float = key("home_mm", 0.0, 2000.0, si=MM)
    park_m: float = key("park_mm", 0.0, 2000.0, si=MM)
    plausibility_spool: float = key("plausibility_spool_pct", 1.0, 100.0, per=PCT)
    plausibility_cycles: int = key("plausibility_cycles", 1, 100000)
    guide_coulomb_n: float = key(GUIDE_COULOMB, name="guide_coulomb_n")
    guide_viscous_ns_m: float = key(GUIDE_VISCOUS, name="guide_viscous_ns_mm")


@frozen
class Identification(Section):
    """HOST_TEST on the test bench (chapter 6.4's experiments)."""
    force_gain_v_n: float = key("force_gain_v_n", 0.0, 10.0)
    force_filter_hz: float = key("force_filter_hz", 0.01, 100.0)
    stroke_guard_m: float = key("stroke_guard_mm", 0.0, 500.0, si=MM)


@frozen
class Hexapod(Section):
    """The platform: its park position, the thesis's gains scaled for it, its payload."""
    park_stroke_m: float = key("park_stroke_mm", 0.0, 2000.0, si=MM)
    kp_factor: float = key("kp_factor", 0.01, 10.0)
    ki_factor: float = key("ki_factor", 0.0, 10.0)
    payload_kg: float = key(PAYLOAD)


@frozen
class Friction(LugreSection):
    """The seals' LuGre law and its observer's gain (eq. 7.30-7.32)."""
    observer_gain_per_s: float = key("observer_gain_per_s", 0.0, 1e4)


@frozen
class Kalman(Section):
    """Each leg's adaptive Kalman filter (eq. 7.41-7.50)."""
    jerk_psd_m2_s5: float = key("jerk_psd_mm2_s5", 1e-3, 1e15, si=MM ** 2)
    adaptive_gain: float = key("adaptive_gain", 0.01, 1e4)
    adaptive_velocity_ref_m_s: float = key("adaptive_velocity_ref_mm_s", 1e-3, 1e4, si=MM)


@frozen
class MassEstimator(Section):
    """The load's mass by RLS (eq. 7.33-7.37)."""
    forgetting: float = key("forgetting", 0.9, 1.0)
    filter_hz: float = key("filter_hz", 0.01, 200.0)
    filter_zeta: float = key("filter_zeta", 0.1, 5.0)
    initial_kg: float = key("initial_kg", 0.0, 100.0)
    covariance_initial: float = key("covariance_initial", 1e-9, 1e6)
    covariance_max: float = key("covariance_max", 1e-9, 1e9)
    mass_max_kg: float = key("mass_max_kg", 0.1, 1000.0)

    def validate(self, where, error) -> None:
        if self.covariance_initial > self.covariance_max:
            raise error(f"{where}.covariance_initial = {self.covariance_initial} exceeds covariance_max = "
                        f"{self.covariance_max}")


@frozen
class LoadPressure(Section):
    """The load pressure's filtered differentiator (eq. 7.38-7.39)."""
    differentiator_hz: float = key("differentiator_hz", 0.1, 240.0)
    differentiator_zeta: float = key("differentiator_zeta", 0.1, 5.0)


@frozen
class Pi(Section):
    """The robust PI (chapter 7.4), gains in V/m and V/(m s); the D term of 7.3's classical
    loops (0 in the PI) on the measurement, through a first-order filter."""
    kp_v_m: float = key("kp_v_mm", 0.0, 100.0, per=MM)
    ki_v_m_s: float = key("ki_v_mm_s", 0.0, 1000.0, per=MM)
    kd_v_s_m: float = key("kd_v_s_mm", 0.0, 10.0, per=MM)
    derivative_filter_hz: float = key("derivative_filter_hz", 1.0, 240.0)
    saturation_v: float = key("saturation_v", 0.01, 24.0)


@frozen
class Adaptive(Section):
    """PI+P scheduled over (position, load) (chapter 7.5, Table 7.2)."""
    kpl_v_pa: float = key("kpl_v_bar", 0.0, 100.0, per=BAR)
    ki_scale: float = key("ki_scale", 0.0, 10.0)
    table_position_m: np.ndarray = numbers("table_position_mm", si=MM)
    table_load_kg: np.ndarray = numbers("table_load_kg")
    kp_0kg_v_m: np.ndarray = numbers("kp_0kg_v_mm", si=1.0 / MM)
    ki_0kg_v_m_s: np.ndarray = numbers("ki_0kg_v_mm_s", si=1.0 / MM)
    kp_3kg_v_m: np.ndarray = numbers("kp_3kg_v_mm", si=1.0 / MM)
    ki_3kg_v_m_s: np.ndarray = numbers("ki_3kg_v_mm_s", si=1.0 / MM)
    kp_6kg_v_m: np.ndarray = numbers("kp_6kg_v_mm", si=1.0 / MM)
    ki_6kg_v_m_s: np.ndarray = numbers("ki_6kg_v_mm_s", si=1.0 / MM)

    @property
    def table_kp(self) -> np.ndarray:
        """(3, n_positions) V/m, the rows the loads of `table_load_kg`."""
        return np.array([self.kp_0kg_v_m, self.kp_3kg_v_m, self.kp_6kg_v_m])

    @property
    def table_ki(self) -> np.ndarray:
        """(3, n_positions) V/(m s), as printed (`ki_scale` applied by the schedule)."""
        return np.array([self.ki_0kg_v_m_s, self.ki_3kg_v_m_s, self.ki_6kg_v_m_s])

    def validate(self, where, error) -> None:
        positions, loads = self.table_position_m, self.table_load_kg
        if len(positions) < 4 or np.any(np.diff(positions) <= 0):
            raise error(f"{where}.table_position_mm must hold >= 4 strictly increasing values")
        if len(loads) != len(SCHEDULE_LOADS) or np.any(np.diff(loads) <= 0) or loads[0] < 0:
            raise error(f"{where}.table_load_kg must hold 3 increasing non-negative masses, got {list(loads)}")
        for load in SCHEDULE_LOADS:
            for name in (f"kp_{load}_v_mm", f"ki_{load}_v_mm_s"):
                values = getattr(self, name.replace("_mm", "_m"))
                if len(values) != len(positions):
                    raise error(f"{where}.{name} has {len(values)} values, table_position_mm has {len(positions)}")
                if values.min() < 0:
                    raise error(f"{where}.{name} has a negative gain {values.min() * MM:g}")


@frozen
class ModelBased(Section):
    """The virtual-work forces along the reference (chapter 11.4.2)."""
    feedforward_scale: float = key("feedforward_scale", 0.0, 10.0)


@dataclass(frozen=True)
class ComputedTorqueGains:
    """One rig's computed-torque gains (docs/EQUATIONS.md "Computed torque")."""
    bandwidth_rad_s: float            # task-space loop: Kp = w^2, Kd = 2 zeta w, Ki = f w^3
    damping: float
    integral_fraction: float
    velocity_gain_per_s: float        # joint error -> commanded piston velocity
    force_bandwidth_rad_s: float      # each leg's force loop on its load cell, scheduled on its operating point
    velocity_filter_hz: float         # low-pass of the measured twist / velocity (the D term)
    force_bandwidth_rest_rad_s: float = math.nan   # ... while the reference rests (NaN: the same)
    velocity_filter_rest_hz: float = math.nan      # ... while the reference rests (NaN: the same)


@frozen
class ComputedTorque(Section):
    """The hexapod's task-space PID through the inverse dynamics and the test bench's one-leg
    law, each rig's gains; the force loops' schedule floor."""
    bandwidth_hz: float = key("bandwidth_hz", 0.1, 50.0)
    damping: float = key("damping", 0.1, 5.0)
    integral_fraction: float = key("integral_fraction", 0.0, 5.0)
    velocity_gain_per_s: float = key("velocity_gain_per_s", 0.0, 1000.0)
    force_bandwidth_hz: float = key("force_bandwidth_hz", 0.0, 100.0)
    force_bandwidth_rest_hz: float = key("force_bandwidth_rest_hz", 0.0, 100.0)
    force_rate_floor: float = key("force_rate_floor_n_s_pct", 1.0, 1e6, si=100.0)   # N/s per unit spool
    velocity_filter_hz: float = key("velocity_filter_hz", 0.5, 200.0)
    velocity_filter_rest_hz: float = key("velocity_filter_rest_hz", 0.5, 200.0)
    stiff_integral_per_s2: float = key("stiff_integral_per_s2", 0.0, 1000.0)
    stiff_rest_hold_s: float = key("stiff_rest_hold_s", 0.0, 100.0)
    stiff_rest_unwind_s: float = key("stiff_rest_unwind_s", 0.0, 100.0)    # 0: never
    windup_share: float = key("windup_capacity_pct", 1.0, 100000.0, si=0.01)
    yaw_bandwidth_hz: float = key("yaw_bandwidth_hz", 0.1, 50.0)
    yaw_damping: float = key("yaw_damping", 0.1, 5.0)
    yaw_blend_s: float = key("yaw_blend_s", 0.01, 100.0)
    imu_max_age_s: float = key("imu_max_age_ms", 0.0, 10000.0, si=1e-3)
    gains_rate_hz: float = key("gains_rate_hz", 1.0, 1000.0)
    testbench_bandwidth_hz: float = key("testbench_bandwidth_hz", 0.1, 50.0)
    testbench_damping: float = key("testbench_damping", 0.1, 5.0)
    testbench_integral_fraction: float = key("testbench_integral_fraction", 0.0, 5.0)
    testbench_velocity_gain_per_s: float = key("testbench_velocity_gain_per_s", 0.0, 1000.0)
    testbench_force_bandwidth_hz: float = key("testbench_force_bandwidth_hz", 0.0, 100.0)
    testbench_velocity_filter_hz: float = key("testbench_velocity_filter_hz", 0.5, 200.0)

    def validate(self, where, error) -> None:
        if self.stiff_integral_per_s2 > 0.0 and self.velocity_gain_per_s <= 0.0:
            raise error(f"{where}.stiff_integral_per_s2 = {self.stiff_integral_per_s2} needs velocity_gain_per_s > 0 "
                        "(it acts through the legs' velocity loop)")

    @cached_property
    def hexapod(self) -> ComputedTorqueGains:
        return ComputedTorqueGains(2 * math.pi * self.bandwidth_hz, self.damping, self.integral_fraction,
                                   self.velocity_gain_per_s, 2 * math.pi * self.force_bandwidth_hz,
                                   self.velocity_filter_hz, 2 * math.pi * self.force_bandwidth_rest_hz,
                                   self.velocity_filter_rest_hz)

    def rate_share(self, period_s: float) -> float:
        """The loop's rate over `gains_rate_hz`, the rate the gains were derived at (at most 1)."""
        return min(1.0, 1.0 / (period_s * self.gains_rate_hz))

    def hexapod_at(self, period_s: float) -> ComputedTorqueGains:
        """The hexapod's gains at a loop of `period_s`: below `gains_rate_hz` the force loops at
        rest slowed in proportion (at 250 Hz, 15 Hz rang: 14 % rms spool; 7.5 Hz holds quietly)."""
        gains = self.hexapod
        share = self.rate_share(period_s)
        if share >= 1.0:
            return gains
        return replace(gains, force_bandwidth_rest_rad_s=share * gains.force_bandwidth_rest_rad_s)

    def yaw_gains(self, period_s: float) -> tuple[float, float]:
        """The hexapod's yaw loop with the IMU: (bandwidth rad/s, damping). It closes on the
        IMU's samples, every 16th SYNC, so below `gains_rate_hz` it is slowed in proportion
        (5 Hz on samples 47 ms apart, at 342 Hz, grows unstable at rest)."""
        return 2 * math.pi * self.yaw_bandwidth_hz * self.rate_share(period_s), self.yaw_damping

    @cached_property
    def testbench(self) -> ComputedTorqueGains:
        return ComputedTorqueGains(2 * math.pi * self.testbench_bandwidth_hz, self.testbench_damping,
                                   self.testbench_integral_fraction, self.testbench_velocity_gain_per_s,
                                   2 * math.pi * self.testbench_force_bandwidth_hz, self.testbench_velocity_filter_hz)


@frozen
class ValveMap(Section):
    """The steady state that holds a leg at hydraulic force F and piston velocity v: its spool
    (fraction of full input) and chamber pressures; rows force_n, columns velocity."""
    force_n: np.ndarray = numbers("force_n")
    velocity_m_s: np.ndarray = numbers("velocity_mm_s", si=MM)
    spool: np.ndarray = table("spool_pct", si=0.01)
    pressure_a_pa: np.ndarray = table("pressure_a_bar", si=BAR)
    pressure_b_pa: np.ndarray = table("pressure_b_bar", si=BAR)
    supply_pressure_pa: float = key(hy.SUPPLY_PRESSURE)       # the supply the map was derived at

    def at_supply(self, supply_pa: float) -> tuple[np.ndarray, ...]:
        """(force_n, velocity_m_s, spool, pressure_a_pa, pressure_b_pa) at another supply, by
        `hydraulics.supply_similarity`: the same spools, the axes and pressures scaled."""
        force, velocity = hy.supply_similarity(supply_pa, self.supply_pressure_pa)
        return (self.force_n * force, self.velocity_m_s * velocity, self.spool, self.pressure_a_pa * force,
                self.pressure_b_pa * force)

    def validate(self, where, error) -> None:
        for name, axis in (("force_n", self.force_n), ("velocity_mm_s", self.velocity_m_s)):
            if axis.ndim != 1 or len(axis) < 2 or np.any(np.diff(axis) <= 0):
                raise error(f"{where}.{name} must hold >= 2 strictly increasing numbers")
        shape = (len(self.force_n), len(self.velocity_m_s))
        for name, values, low, high in (("spool_pct", self.spool, -1.0, 1.0),
                                        ("pressure_a_bar", self.pressure_a_pa, -BAR, 1e3 * BAR),
                                        ("pressure_b_bar", self.pressure_b_pa, -BAR, 1e3 * BAR)):
            if values.ndim != 2 or values.shape != shape:
                raise error(f"{where}.{name} is {'x'.join(map(str, values.shape))}, force_n x velocity_mm_s is "
                            f"{shape[0]}x{shape[1]}")
            scale = 0.01 if name == "spool_pct" else BAR
            if not np.all((values >= low) & (values <= high)):
                raise error(f"{where}.{name} holds a value outside [{low / scale:g}, {high / scale:g}]")


@frozen
class HydraulicModel(hy.ValveSection, hy.ChamberSection):
    """The controller's model of each actuator's valve and chambers (the emulator's [valve]
    and [chambers] keys) and the power unit's pressures: what the residuals run."""
    supply_pressure_pa: float = key(hy.SUPPLY_PRESSURE)
    tank_pressure_pa: float = key(hy.TANK_PRESSURE)

    def validate(self, where, error) -> None:
        if self.tank_pressure_pa >= self.supply_pressure_pa:
            raise error(f"{where}.tank_pressure_bar = {self.tank_pressure_pa / BAR:g} must be below "
                        f"supply_pressure_bar = {self.supply_pressure_pa / BAR:g}")


@frozen
class Residuals(Section):
    """Each actuator's chamber model against its load cell, its spool and its pressures."""
    enabled: bool = flag("enabled")
    correction_gain: float = key("correction_gain", 0.001, 1.0)
    filter_s: float = key("filter_ms", 0.1, 1000.0, si=MS)
    persistence_cycles: int = key("persistence_cycles", 1, 10000)
    flow_spread: float = key("flow_spread_pct", 0.0, 100.0, per=PCT)
    supply_legs: int = key("supply_legs", 2, 6)
    supply_tolerance_pa: float = key("supply_tolerance_bar", 0.01, 100.0, si=BAR)
    load_cell_noise_n: float = key(LOAD_CELL_NOISE)
    spool_check: bool = flag("spool_check")
    spool_floor: float = key("spool_floor_pct", 0.1, 100.0, per=PCT)
    spool_lag_spread: float = key("spool_lag_spread_pct", 0.0, 99.0, per=PCT)
    spool_persistence_cycles: int = key("spool_persistence_cycles", 1, 10000)
    column_stiffness_n_m: float = key("column_stiffness_n_mm", 0.1, 1e6, per=MM)
    leakage_spread: float = key("leakage_spread_pct", 0.0, 100.0, per=PCT)
    stiffness_spread: float = key("stiffness_spread_pct", 0.0, 99.0, per=PCT)
    pressure_noise_pa: float = key(PRESSURE_NOISE)
    pressure_persistence_samples: int = key("pressure_persistence_samples", 1, 100)
    pressure_carry: float = key("pressure_carry", 0.0, 1.0)


@frozen
class Limits(Section):
    """The legs' limits while the valves follow the controller."""
    stroke_margin_m: float = key("stroke_margin_mm", 0.0, 100.0, si=MM)
    velocity_max_m_s: float = key("velocity_max_mm_s", 1.0, 1e4, si=MM)
    force_max_n: float = key("force_max_n", 1.0, 1e6)
    tracking_error_max_m: float = key("tracking_error_max_mm", 0.1, 1000.0, si=MM)
    platform_error_max_m: float = key("platform_error_max_mm", 0.1, 1000.0, si=MM)
    platform_angle_max_rad: float = key("platform_angle_max_deg", 0.01, 90.0, si=math.pi / 180.0)
    spool_max: float = key("spool_max_pct", 1.0, 100.0, per=PCT)


@frozen
class Supervisor(Section):
    """The state machine's own settings and the loop's and frames' fault counts."""
    auto_enable: bool = flag("auto_enable")
    homing_speed_m_s: float = key("homing_speed_mm_s", 0.1, 1000.0, si=MM)
    homing_accel_time_s: float = key("homing_accel_time_s", 0.001, 10.0)
    missing_frames_fault: int = key("missing_frames_fault", 1, 10000)
    e2e_errors_fault: int = key("e2e_errors_fault", 1, 10000)
    overruns_fault: int = key("overruns_fault", 1, 10000)
    controlled_stop_s: float = key("controlled_stop_ms", 0.0, 5000.0, si=MS)


@frozen
class Kinematics(Section):
    """The hexapod's direct kinematics every cycle and its singularity check."""
    dk_tolerance_m: float = key("dk_tolerance_um", 0.001, 1000.0, si=US)
    dk_max_iterations: int = key("dk_max_iterations", 1, 100)
    dk_failures_fault: int = key("dk_failures_fault", 1, 10000)
    singularity_ratio_min: float = key("singularity_ratio_min", 0.0, 1.0)


@frozen
class Payload(Section):
    """The hexapod's payload identified from the load cells (motion_control/payload.py), from
    [hexapod] payload_kg as declared, at the platform's centre of mass."""
    estimate: bool = flag("estimate")
    forgetting: float = key("forgetting", 0.9, 1.0)
    covariance_initial: float = key("covariance_initial", 1e-6, 1e6)
    covariance_max: float = key("covariance_max", 1e-6, 1e9)
    mass_max_kg: float = key("mass_max_kg", 0.1, 1000.0)
    com_mass_min_kg: float = key("com_mass_min_kg", 0.0, 100.0)
    com_reach_m: float = key("com_reach_mm", 1.0, 2000.0, si=MM)
    accel_gate_m_s2: float = key("accel_gate_m_s2", 0.0, 100.0)
    innovation_max_n: float = key("innovation_max_n", 1.0, 1e5)

    def validate(self, where, error) -> None:
        if self.covariance_initial > self.covariance_max:
            raise error(f"{where}.covariance_initial = {self.covariance_initial} exceeds covariance_max = "
                        f"{self.covariance_max}")


@frozen
class Waypoints(Section):
    """The host's waypoint queue and each waypoint's admission check."""
    queue: int = key("queue", 1, 255)
    velocity_max_m_s: float = key("velocity_max_mm_s", 0.1, 1e4, si=MM)
    step_max_m: float = key("step_max_mm", 0.0, 300.0, si=MM)
    capacity_share: float = key("capacity_share_pct", 10.0, 100.0, per=PCT)
    supply_share: float = key("supply_share_pct", 10.0, 100.0, per=PCT)
    lag_max_m: float = key("lag_max_mm", 0.01, 100.0, si=MM)
    lag_angle_max_rad: float = key("lag_angle_max_deg", 0.01, 90.0, si=math.pi / 180.0)

    @property
    def angle_weight_m_rad(self) -> float:
        """A rotation error weighs as this many metres of position error per radian."""
        return self.lag_max_m / self.lag_angle_max_rad
    path_samples: int = key("path_samples", 2, 1000)


@frozen
class TimeScaling(Section):
    """The hexapod's reference clock slowed online while a valve's command is at its limit or
    the supply has fallen below the waypoint check's share of it (motion_control/time_scaling.py)."""
    enabled: bool = flag("enabled")
    rate_min: float = key("rate_min_pct", 5.0, 100.0, per=PCT)
    slow_per_s: float = key("slow_per_s", 0.01, 100.0)
    recover_per_s: float = key("recover_per_s", 0.01, 100.0)
    hold_s: float = key("hold_ms", 0.0, 1000.0, si=MS)


@frozen
class Plausibility(Section):
    """The legs' motion against their valve input, the encoders' attitude against the IMU's."""
    spool: float = key("spool_pct", 1.0, 100.0, per=PCT)
    cycles: int = key("cycles", 1, 100000)
    travel_m: float = key("travel_mm", 0.0, 1000.0, si=MM)
    overrun_share: float = key("overrun_pct", 1.0, 100.0, per=PCT)
    attitude_mismatch_rad: float = key("attitude_mismatch_deg", 0.01, 90.0, si=math.pi / 180.0)
    attitude_mismatch_samples: int = key("attitude_mismatch_samples", 1, 10000)


@frozen
class ControllerConfig(ConfigFile):
    timing: Timing
    devices: Devices
    actuator: Actuator
    testbench: Testbench
    identification: Identification
    hexapod: Hexapod
    friction: Friction
    kalman: Kalman
    mass_estimator: MassEstimator
    load_pressure: LoadPressure
    pi: Pi
    adaptive: Adaptive
    model_based: ModelBased
    computed_torque: ComputedTorque
    valve_map: ValveMap
    hydraulic_model: HydraulicModel
    power_unit: pu.PowerUnitSection
    residuals: Residuals
    limits: Limits
    supervisor: Supervisor
    kinematics: Kinematics
    waypoints: Waypoints
    payload: Payload
    time_scaling: TimeScaling
    plausibility: Plausibility

    @cached_property
    def hydraulics(self) -> np.ndarray:
        """The actuators' parameter vector (physics.hydraulics HP_*) from [actuator] and
        [hydraulic_model]: what the residuals and the computed torque's force loops run."""
        return hy.pack(self.actuator, self.hydraulic_model, self.hydraulic_model,
                       self.hydraulic_model.tank_pressure_pa)

    @property
    def supply_refill_s(self) -> float:
        """How long the pump takes to refill the accumulator from the lowest supply a move may
        leave without a fault (the flow band's edge, `SupplyPressure`: (1 - flow_spread)^2 of
        the drop over the tank), with half as long again for the relief."""
        set_pa, tank_pa = self.hydraulic_model.supply_pressure_pa, self.hydraulic_model.tank_pressure_pa
        lowest = tank_pa + (1.0 - self.residuals.flow_spread) ** 2 * (set_pa - tank_pa)
        return 1.5 * pu.usable_volume(self.power, set_pa, lowest) / self.power_unit.pump_flow_m3_s

    @cached_property
    def power(self) -> np.ndarray:
        """The power unit's parameter vector (physics.power_unit PU_*), set at [hydraulic_model]'s
        supply: what the waypoint check's flow budget runs."""
        return pu.pack(self.power_unit, self.hydraulic_model.supply_pressure_pa)


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> ControllerConfig:
    return load_file(ControllerConfig, default_config_path(), path, overrides, ConfigError)
