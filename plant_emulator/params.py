"""The emulator's configuration: packaged defaults (`data/emulator.toml`, thesis units) plus
an optional user file with the same sections and keys, validated and converted to SI once.

Every key has an allowed range below; an unknown section or key, a wrong type or a value
out of range is a `ConfigError` (one line naming the file, the key, the value and the
range; the CLI turns it into exit code 2).
"""

from __future__ import annotations

import math
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np

from physics import hydraulics as hy
from physics import lugre
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
from physics.constants import MM
from program import sections
from program.errors import UserInputError
from program.realtime import CPU_LATENCY, REALTIME_PRIORITY
from program.sections import ConfigFile, Section, flag, frozen, key, load_file, load_layered, numbers
from protocol.devices import IMU_EDS, LEG_EDS, check_files
from protocol.nodes import HEARTBEAT

US, MS = 1e-6, 1e-3
# lockstep pacing: the valves' SYNC watchdog, in periods of the clock: longer than the
# controller's lockstep wait for a cycle's frames (`lockstep_timeout_ms`), which a silent
# emulator makes it sit out
LOCKSTEP_SYNC_TIMEOUT_PERIODS = 5000.0


class ConfigError(UserInputError):
    """A configuration value the emulator cannot use."""


def default_config_path() -> Path:
    return Path(str(resources.files("plant_emulator").joinpath("data/emulator.toml")))


@frozen
class Actuator(CylinderSection):
    """Each leg's cylinder (chapter 4.2), its moving parts, the power unit, the valve input."""
    piston_rod_mass_kg: float = key("piston_rod_mass_kg", 0.01, 50.0)
    supply_pressure_pa: float = key(hy.SUPPLY_PRESSURE)
    tank_pressure_pa: float = key(hy.TANK_PRESSURE)
    valve_full_scale_v: float = key(VALVE_FULL_SCALE)

    def validate(self, where, error) -> None:
        super().validate(where, error)
        if self.tank_pressure_pa >= self.supply_pressure_pa:
            raise error(f"{where}.tank_pressure_bar must be below supply_pressure_bar")


@frozen
class Guide(Section):
    """The test bench's linear guide, Table D.1 / eq. D.3 (Fs and vs tabulated over the load)."""
    slide_mass_kg: float = key(SLIDE_MASS)
    coulomb_n: float = key(GUIDE_COULOMB)
    viscous_ns_m: float = key(GUIDE_VISCOUS)
    exponent: float = key("stribeck_exponent", 0.5, 10.0)
    bristle_n_m: float = key("bristle_stiffness_n_mm", 0.01, 1e6, per=MM)
    damping_ratio: float = key("bristle_damping_ratio", 0.0, 10.0)
    table_mass_kg: np.ndarray = numbers("table_mass_kg")
    table_static_n: np.ndarray = numbers("table_static_n")
    table_stribeck_m_s: np.ndarray = numbers("table_stribeck_mm_s", si=MM)

    def validate(self, where, error) -> None:
        masses, static, stribeck = self.table_mass_kg, self.table_static_n, self.table_stribeck_m_s
        if not (len(masses) == len(static) == len(stribeck)):
            raise error(f"{where} table_mass_kg, table_static_n, table_stribeck_mm_s differ in length")
        if np.any(np.diff(masses) <= 0) or masses[0] < 0:
            raise error(f"{where}.table_mass_kg must be non-negative and increasing")
        if np.any(static < self.coulomb_n) or np.any(stribeck <= 0):
            raise error(f"{where} static friction must be >= coulomb_n and Stribeck velocities > 0")

    def lugre_vector(self, load_kg: float) -> np.ndarray:
        """eq. D.3 as LuGre parameters for an external mass (Fs, vs interpolated in the table)."""
        fs = float(np.interp(load_kg, self.table_mass_kg, self.table_static_n))
        vs = float(np.interp(load_kg, self.table_mass_kg, self.table_stribeck_m_s))
        mass = self.slide_mass_kg + load_kg
        # eq. 6.12: sigma1 = 2 zeta sqrt(sigma0 m) - sigma2, for a well-behaved stick-slip
        sigma1 = max(2.0 * self.damping_ratio * math.sqrt(self.bristle_n_m * mass) - self.viscous_ns_m, 0.0)
        fc = self.coulomb_n
        return lugre.pack(fc, fs - fc, vs, self.viscous_ns_m, -fc, -(fs - fc), vs, self.viscous_ns_m,
                          self.bristle_n_m, sigma1, self.bristle_n_m, sigma1, self.exponent)


@frozen
class Testbench(Section):
    load_kg: float = key("load_kg", 0.0, 65.0)                # on the slide
    substep_s: float = key("substep_us", 1.0, 500.0, si=US)


@frozen
class Hexapod(Section):
    payload_kg: float = key(PAYLOAD)
    mujoco_timestep_s: float = key("mujoco_timestep_us", 50.0, 2000.0, si=US)
    hydraulic_substeps: int = key("hydraulic_substeps", 1, 50)


@frozen
class Sensors(Section):
    """What each leg's transducers and the IMU add to the truth (chapter 8.2.3)."""
    encoder_resolution_m: float = key(ENCODER_RESOLUTION)
    load_cell_noise_n: float = key(LOAD_CELL_NOISE)
    pressure_noise_pa: float = key(PRESSURE_NOISE)
    imu_angle_noise_rad: float = key("imu_angle_noise_rad", 0.0, 0.1)
    imu_rate_noise_rad_s: float = key("imu_rate_noise_rad_s", 0.0, 1.0)
    seed: int = key("seed", 0, 2**31 - 1)


@frozen
class Nodes(Section):
    """The CiA 408 valve drivers and sensor nodes on the bus, and the process's pacing."""
    sync_period_s: float = key("sync_period_ms", 0.5, 100.0, si=MS)
    command_timeout_syncs: int = key("command_timeout_syncs", 1, 1000)
    sync_timeout_periods: float = key("sync_timeout_periods", 1.0, 10000.0)
    heartbeat_s: float = key(HEARTBEAT)
    nmt_autostart: bool = flag("nmt_autostart")
    hold_blocks_ports: bool = flag("hold_blocks_ports")
    spool_jam_threshold: float = key("spool_jam_threshold_pct", 0.1, 100.0, per=100.0)
    spool_jam_syncs: int = key("spool_jam_syncs", 1, 10000)
    leg_pressure_divisor: int = key("leg_pressure_divisor", 0, 240)
    imu_divisor: int = key("imu_divisor", 0, 240)
    valve_status_divisor: int = key("valve_status_divisor", 0, 240)
    realtime_priority: int = key(REALTIME_PRIORITY)
    cpu_latency_us: int = key(CPU_LATENCY)
    leg_eds: str = key(LEG_EDS)
    imu_eds: str = key(IMU_EDS)

    def validate(self, where: str, error: type[UserInputError]) -> None:
        check_files((self.leg_eds, self.imu_eds), where, error)


@frozen
class EmulatorConfig(ConfigFile):
    actuator: Actuator
    valve: hy.ValveSection
    chambers: hy.ChamberSection
    power_unit: pu.PowerUnitSection
    friction: lugre.LugreSection
    guide: Guide
    testbench: Testbench
    hexapod: Hexapod
    sensors: Sensors
    nodes: Nodes

    @cached_property
    def hp(self) -> np.ndarray:
        """Each actuator's hydraulics parameter vector (SI)."""
        return hy.pack(self.actuator, self.valve, self.chambers, self.actuator.tank_pressure_pa)

    @cached_property
    def pu(self) -> np.ndarray:
        """The power unit's parameter vector (SI), its relief set at the actuators' supply."""
        return pu.pack(self.power_unit, self.actuator.supply_pressure_pa)

    @property
    def area_a_m2(self) -> float:
        return float(self.hp[hy.HP_AREA_A])

    @property
    def alpha(self) -> float:
        return float(self.hp[hy.HP_ALPHA])

    @property
    def stroke_m(self) -> float:
        return float(self.hp[hy.HP_STROKE])


def merge(base: dict, override: dict, source: str) -> dict:
    """`base` (thesis units) with `override` applied; every override key validated."""
    return sections.merge(EmulatorConfig.schema(), base, override, source, ConfigError)


def load_raw(path: str | Path | None = None, overrides: dict | None = None) -> dict:
    """Defaults, then the user's file, then programmatic overrides; thesis units."""
    return load_layered(EmulatorConfig.schema(), default_config_path(), path, overrides, ConfigError)


def build(raw: dict, source: str = "config") -> EmulatorConfig:
    """The sections of merged, validated values (thesis units): a run's emulator.toml."""
    return EmulatorConfig.build(raw, source, ConfigError)


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> EmulatorConfig:
    return load_file(EmulatorConfig, default_config_path(), path, overrides, ConfigError)
