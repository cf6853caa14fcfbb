"""The emulator's configuration: packaged defaults (`data/emulator.toml`, thesis units) plus
an optional user file with the same sections and keys, validated and converted to SI once.

Every key has an allowed range below; an unknown section or key, a wrong type or a value
out of range is a `ConfigError` (one line naming the file, the key, the value and the
range; the CLI turns it into exit code 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from physics import hydraulics as hy
from physics import lugre
from physics.constants import BAR, MM
from program.errors import UserInputError
from program.tomlconfig import load_layered
from program.tomlconfig import merge as _merge

# (low, high) per key; ints are declared with int bounds. Lists are checked separately.
RANGES: dict[str, dict[str, tuple]] = {
    "actuator": {
        "bore_radius_mm": (0.5, 100.0), "rod_radius_mm": (0.1, 99.0), "stroke_mm": (10.0, 2000.0),
        "piston_rod_mass_kg": (0.01, 50.0), "supply_pressure_bar": (0.0, 40.0),
        "tank_pressure_bar": (0.0, 10.0), "valve_full_scale_v": (0.01, 10.0),
    },
    "valve": hy.VALVE_RANGES,
    "chambers": hy.CHAMBER_RANGES,
    "friction": {
        "alpha0_pos_n": (-1000.0, 1000.0), "alpha1_pos_n": (-1000.0, 1000.0), "vs_pos_mm_s": (0.01, 1e4),
        "sigma2_pos_ns_mm": (0.0, 100.0), "alpha0_neg_n": (-1000.0, 1000.0), "alpha1_neg_n": (-1000.0, 1000.0),
        "vs_neg_mm_s": (-1e4, -0.01), "sigma2_neg_ns_mm": (0.0, 100.0), "sigma0_pos_n_mm": (1e-3, 1e6),
        "sigma1_pos_ns_mm": (0.0, 1e3), "sigma0_neg_n_mm": (1e-3, 1e6), "sigma1_neg_ns_mm": (0.0, 1e3),
    },
    "guide": {
        "slide_mass_kg": (0.01, 100.0), "coulomb_n": (0.0, 1000.0), "viscous_ns_mm": (0.0, 100.0),
        "stribeck_exponent": (0.5, 10.0), "bristle_stiffness_n_mm": (0.01, 1e6),
        "bristle_damping_ratio": (0.0, 10.0), "table_mass_kg": None, "table_static_n": None,
        "table_stribeck_mm_s": None,
    },
    "testbench": {"load_kg": (0.0, 65.0), "substep_us": (1.0, 500.0)},
    "hexapod": {"payload_kg": (0.0, 65.0), "mujoco_timestep_us": (50.0, 2000.0),
                "hydraulic_substeps": (1, 50)},
    "sensors": {
        "encoder_resolution_mm": (0.001, 10.0), "load_cell_noise_n": (0.0, 100.0),
        "pressure_noise_bar": (0.0, 10.0), "imu_angle_noise_rad": (0.0, 0.1),
        "imu_rate_noise_rad_s": (0.0, 1.0), "seed": (0, 2**31 - 1),
    },
    "nodes": {
        "sync_period_ms": (0.5, 100.0), "command_timeout_syncs": (1, 1000),
        "sync_timeout_periods": (1.0, 10000.0), "heartbeat_ms": (10.0, 10000.0), "nmt_autostart": bool,
        "hold_blocks_ports": bool,
        "spool_jam_threshold_pct": (0.1, 100.0), "spool_jam_syncs": (1, 10000),
        "leg_pressure_divisor": (0, 240), "imu_divisor": (0, 240), "valve_status_divisor": (0, 240),
        "realtime_priority": (1, 99), "cpu_latency_us": (-1, 100000),
    },
}


class ConfigError(UserInputError):
    """A configuration value the emulator cannot use."""


def default_config_path() -> Path:
    return Path(str(resources.files("plant_emulator").joinpath("data/emulator.toml")))


def merge(base: dict, override: dict, source: str) -> dict:
    """`base` with `override` applied; every override key validated."""
    return _merge(RANGES, base, override, source, ConfigError)


def load_raw(path: str | Path | None = None, overrides: dict | None = None) -> dict:
    """Defaults, then the user's file, then programmatic overrides; thesis units."""
    return load_layered(RANGES, default_config_path(), path, overrides, ConfigError)


@dataclass(frozen=True)
class GuideParams:
    slide_mass_kg: float
    coulomb_n: float
    viscous_ns_m: float
    exponent: float
    table_mass_kg: np.ndarray
    table_static_n: np.ndarray
    table_stribeck_m_s: np.ndarray
    bristle_n_m: float
    damping_ratio: float

    def lugre_vector(self, load_kg: float) -> np.ndarray:
        """eq. D.3 as LuGre parameters for an external mass (Fs, vs interpolated in [guide]'s table)."""
        fs = float(np.interp(load_kg, self.table_mass_kg, self.table_static_n))
        vs = float(np.interp(load_kg, self.table_mass_kg, self.table_stribeck_m_s))
        mass = self.slide_mass_kg + load_kg
        # eq. 6.12: sigma1 = 2 zeta sqrt(sigma0 m) - sigma2, for a well-behaved stick-slip
        sigma1 = max(2.0 * self.damping_ratio * math.sqrt(self.bristle_n_m * mass) - self.viscous_ns_m, 0.0)
        fc = self.coulomb_n
        return lugre.pack(fc, fs - fc, vs, self.viscous_ns_m, -fc, -(fs - fc), vs, self.viscous_ns_m,
                          self.bristle_n_m, sigma1, self.bristle_n_m, sigma1, self.exponent)


@dataclass(frozen=True)
class EmulatorConfig:
    raw: dict                        # thesis units, as loaded
    hp: np.ndarray                   # hydraulics parameter vector (SI)
    friction: np.ndarray             # LuGre vector of the cylinder (SI)
    guide: GuideParams
    supply_pressure_pa: float
    valve_full_scale_v: float
    piston_rod_mass_kg: float
    load_kg: float
    substep_s: float
    payload_kg: float
    mujoco_timestep_s: float
    hydraulic_substeps: int
    encoder_resolution_m: float
    load_cell_noise_n: float
    pressure_noise_pa: float
    imu_angle_noise_rad: float
    imu_rate_noise_rad_s: float
    seed: int
    sync_period_s: float
    command_timeout_syncs: int
    sync_timeout_periods: float
    heartbeat_s: float
    nmt_autostart: bool
    hold_blocks_ports: bool
    spool_jam_threshold: float
    spool_jam_syncs: int
    leg_pressure_divisor: int
    realtime_priority: int
    cpu_latency_us: int               # --realtime: PM QoS wake-up latency asked of the CPUs (-1: none)
    imu_divisor: int
    valve_status_divisor: int

    @property
    def area_a_m2(self) -> float:
        return float(self.hp[hy.HP_AREA_A])

    @property
    def alpha(self) -> float:
        return float(self.hp[hy.HP_ALPHA])

    @property
    def stroke_m(self) -> float:
        return float(self.hp[hy.HP_STROKE])


def pack_hydraulics(raw: dict) -> np.ndarray:
    a, v, c = raw["actuator"], raw["valve"], raw["chambers"]
    if a["rod_radius_mm"] >= a["bore_radius_mm"]:
        raise ConfigError(f"config: [actuator].rod_radius_mm = {a['rod_radius_mm']} must be below "
                          f"bore_radius_mm = {a['bore_radius_mm']}")
    hp = hy.pack(a, v, c)
    if a["tank_pressure_bar"] >= a["supply_pressure_bar"] > 0:
        raise ConfigError("config: [actuator].tank_pressure_bar must be below supply_pressure_bar")
    return hp


def pack_friction(raw: dict) -> np.ndarray:
    try:
        return lugre.from_table(raw["friction"])
    except ValueError as error:
        raise ConfigError(f"config: [friction]: {error}") from None


def guide_params(raw: dict) -> GuideParams:
    g = raw["guide"]
    masses, static, stribeck = (np.asarray(g[k], dtype=float) for k in
                                ("table_mass_kg", "table_static_n", "table_stribeck_mm_s"))
    if not (len(masses) == len(static) == len(stribeck)):
        raise ConfigError("config: [guide] table_mass_kg, table_static_n, table_stribeck_mm_s differ in length")
    if np.any(np.diff(masses) <= 0) or masses[0] < 0:
        raise ConfigError("config: [guide].table_mass_kg must be non-negative and increasing")
    if np.any(static < g["coulomb_n"]) or np.any(stribeck <= 0):
        raise ConfigError("config: [guide] static friction must be >= coulomb_n and Stribeck velocities > 0")
    return GuideParams(g["slide_mass_kg"], g["coulomb_n"], g["viscous_ns_mm"] / MM, g["stribeck_exponent"],
                       masses, static, stribeck * MM, g["bristle_stiffness_n_mm"] / MM,
                       g["bristle_damping_ratio"])


def build(raw: dict) -> EmulatorConfig:
    a, t, h, s, n = raw["actuator"], raw["testbench"], raw["hexapod"], raw["sensors"], raw["nodes"]
    return EmulatorConfig(
        raw=raw, hp=pack_hydraulics(raw), friction=pack_friction(raw), guide=guide_params(raw),
        supply_pressure_pa=a["supply_pressure_bar"] * BAR, valve_full_scale_v=a["valve_full_scale_v"],
        piston_rod_mass_kg=a["piston_rod_mass_kg"], load_kg=t["load_kg"], substep_s=t["substep_us"] * 1e-6,
        payload_kg=h["payload_kg"], mujoco_timestep_s=h["mujoco_timestep_us"] * 1e-6,
        hydraulic_substeps=h["hydraulic_substeps"],
        encoder_resolution_m=s["encoder_resolution_mm"] * MM, load_cell_noise_n=s["load_cell_noise_n"],
        pressure_noise_pa=s["pressure_noise_bar"] * BAR, imu_angle_noise_rad=s["imu_angle_noise_rad"],
        imu_rate_noise_rad_s=s["imu_rate_noise_rad_s"], seed=s["seed"],
        sync_period_s=n["sync_period_ms"] * 1e-3, command_timeout_syncs=n["command_timeout_syncs"],
        sync_timeout_periods=n["sync_timeout_periods"], heartbeat_s=n["heartbeat_ms"] * 1e-3,
        nmt_autostart=n["nmt_autostart"], hold_blocks_ports=n["hold_blocks_ports"],
        spool_jam_threshold=n["spool_jam_threshold_pct"] / 100.0,
        spool_jam_syncs=n["spool_jam_syncs"], leg_pressure_divisor=n["leg_pressure_divisor"],
        imu_divisor=n["imu_divisor"], valve_status_divisor=n["valve_status_divisor"],
        realtime_priority=n["realtime_priority"], cpu_latency_us=n["cpu_latency_us"],
    )


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> EmulatorConfig:
    return build(load_raw(path, overrides))
