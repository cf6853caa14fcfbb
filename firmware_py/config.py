"""The controller's configuration: `data/controller.toml` (thesis units) plus an optional
user file with the same sections and keys, validated against the ranges below and
converted to SI once (`load_config`). Errors are one line naming the file, the key, the
value and the allowed range (`ConfigError`; the CLI exits 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from physics import hydraulics as hy
from physics import lugre
from physics.actuator import cylinder_areas
from physics.constants import BAR, MM
from program.errors import UserInputError
from program.tomlconfig import TABLE, load_layered

RANGES: dict[str, dict[str, object]] = {
    "timing": {
        "sync_window_fraction": (0.1, 0.95), "spin_us": (0.0, 5000.0),
        "commit_room_us": (0.0, 100000.0), "lockstep_timeout_ms": (1.0, 10000.0),
        "activation_timeout_s": (0.1, 600.0), "hold_cycles": (1, 10000), "shutdown_hold_cycles": (1, 10000),
        "shutdown_disable_cycles": (1, 10000), "heartbeat_ms": (10.0, 10000.0),
        "heartbeat_timeout_ms": (10.0, 60000.0), "realtime_priority": (1, 99),
        "cpu": (-1, 1023), "cpu_latency_us": (-1, 100000), "stall_fault_periods": (1.0, 10000.0),
    },
    "actuator": {
        "bore_radius_mm": (0.5, 100.0), "rod_radius_mm": (0.1, 99.0), "stroke_mm": (10.0, 2000.0),
        "moving_mass_kg": (0.0, 50.0), "valve_full_scale_v": (0.01, 24.0), "encoder_resolution_mm": (1e-4, 10.0),
    },
    "testbench": {"slide_mass_kg": (0.0, 100.0), "home_mm": (0.0, 2000.0), "park_mm": (0.0, 2000.0),
                  "plausibility_spool_pct": (1.0, 100.0), "plausibility_cycles": (1, 100000),
                  "guide_coulomb_n": (0.0, 1000.0), "guide_viscous_ns_mm": (0.0, 100.0)},
    "identification": {"force_gain_v_n": (0.0, 10.0), "force_filter_hz": (0.01, 100.0),
                       "stroke_guard_mm": (0.0, 500.0)},
    "hexapod": {"park_stroke_mm": (0.0, 2000.0), "kp_factor": (0.01, 10.0), "ki_factor": (0.0, 10.0),
                "payload_kg": (0.0, 500.0)},
    "friction": {
        "alpha0_pos_n": (-1000.0, 1000.0), "alpha1_pos_n": (-1000.0, 1000.0), "vs_pos_mm_s": (0.01, 1e4),
        "sigma2_pos_ns_mm": (0.0, 100.0), "alpha0_neg_n": (-1000.0, 1000.0), "alpha1_neg_n": (-1000.0, 1000.0),
        "vs_neg_mm_s": (-1e4, -0.01), "sigma2_neg_ns_mm": (0.0, 100.0), "sigma0_pos_n_mm": (1e-3, 1e6),
        "sigma1_pos_ns_mm": (0.0, 1e3), "sigma0_neg_n_mm": (1e-3, 1e6), "sigma1_neg_ns_mm": (0.0, 1e3),
        "observer_gain_per_s": (0.0, 1e4),
    },
    "kalman": {"jerk_psd_mm2_s5": (1e-3, 1e15), "adaptive_gain": (0.01, 1e4),
               "adaptive_velocity_ref_mm_s": (1e-3, 1e4)},
    "mass_estimator": {
        "forgetting": (0.9, 1.0), "filter_hz": (0.01, 200.0), "filter_zeta": (0.1, 5.0), "initial_kg": (0.0, 100.0),
        "covariance_initial": (1e-9, 1e6), "covariance_max": (1e-9, 1e9), "mass_max_kg": (0.1, 1000.0),
    },
    "load_pressure": {"differentiator_hz": (0.1, 240.0), "differentiator_zeta": (0.1, 5.0)},
    "pi": {"kp_v_mm": (0.0, 100.0), "ki_v_mm_s": (0.0, 1000.0), "saturation_v": (0.01, 24.0)},
    "adaptive": {
        "kpl_v_bar": (0.0, 100.0), "ki_scale": (0.0, 10.0), "table_position_mm": None, "table_load_kg": None,
        "kp_0kg_v_mm": None, "ki_0kg_v_mm_s": None, "kp_3kg_v_mm": None, "ki_3kg_v_mm_s": None,
        "kp_6kg_v_mm": None, "ki_6kg_v_mm_s": None,
    },
    "model_based": {"feedforward_scale": (0.0, 10.0)},
    "computed_torque": {
        "bandwidth_hz": (0.1, 50.0), "damping": (0.1, 5.0), "integral_fraction": (0.0, 5.0),
        "velocity_gain_per_s": (0.0, 1000.0),
        "force_bandwidth_hz": (0.0, 100.0), "force_rate_floor_n_s_pct": (1.0, 1e6),
        "testbench_bandwidth_hz": (0.1, 50.0), "testbench_damping": (0.1, 5.0),
        "testbench_integral_fraction": (0.0, 5.0), "testbench_velocity_gain_per_s": (0.0, 1000.0),
        "testbench_force_bandwidth_hz": (0.0, 100.0), "testbench_velocity_filter_hz": (0.5, 200.0),
        "velocity_filter_hz": (0.5, 200.0),
    },
    "valve_map": {"force_n": None, "velocity_mm_s": None, "spool_pct": TABLE, "pressure_a_bar": TABLE,
                  "pressure_b_bar": TABLE},
    "hydraulic_model": {**hy.VALVE_RANGES, **hy.CHAMBER_RANGES, "supply_pressure_bar": (1.0, 400.0),
                        "tank_pressure_bar": (0.0, 10.0)},
    "residuals": {"enabled": bool, "correction_gain": (0.001, 1.0), "filter_ms": (0.1, 1000.0),
                  "persistence_cycles": (1, 10000), "flow_spread_pct": (0.0, 100.0), "supply_legs": (2, 6),
                  "load_cell_noise_n": (0.0, 100.0), "spool_check": bool, "spool_floor_pct": (0.1, 100.0),
                  "spool_lag_spread_pct": (0.0, 99.0), "spool_persistence_cycles": (1, 10000),
                  "column_stiffness_n_mm": (0.1, 1e6), "leakage_spread_pct": (0.0, 100.0),
                  "stiffness_spread_pct": (0.0, 99.0), "pressure_noise_bar": (0.0, 10.0),
                  "pressure_persistence_samples": (1, 100)},
    "limits": {
        "stroke_margin_mm": (0.0, 100.0), "velocity_max_mm_s": (1.0, 1e4), "force_max_n": (1.0, 1e6),
        "tracking_error_max_mm": (0.1, 1000.0), "spool_max_pct": (1.0, 100.0),
    },
    "supervisor": {
        "missing_frames_fault": (1, 10000), "e2e_errors_fault": (1, 10000), "overruns_fault": (1, 10000),
        "dk_failures_fault": (1, 10000), "dk_tolerance_um": (0.001, 1000.0), "dk_max_iterations": (1, 100),
        "singularity_ratio_min": (0.0, 1.0), "auto_enable": bool, "homing_speed_mm_s": (0.1, 1000.0),
        "homing_accel_time_s": (0.001, 10.0), "waypoint_queue": (1, 255),
        "waypoint_velocity_max_mm_s": (0.1, 1e4), "waypoint_step_max_mm": (0.0, 300.0),
        "waypoint_force_max_n": (1.0, 1e6),
        "waypoint_path_samples": (2, 1000), "plausibility_spool_pct": (1.0, 100.0),
        "plausibility_cycles": (1, 100000), "plausibility_travel_mm": (0.0, 1000.0),
        "attitude_mismatch_deg": (0.01, 90.0), "attitude_mismatch_samples": (1, 10000),
        "controlled_stop_ms": (0.0, 5000.0),
    },
}
SCHEDULE_LOADS = ("0kg", "3kg", "6kg")


class ConfigError(UserInputError):
    """A configuration value the controller cannot use."""


def default_config_path() -> Path:
    return Path(str(resources.files("firmware_py").joinpath("data/controller.toml")))


@dataclass(frozen=True)
class ComputedTorqueGains:
    """One rig's computed-torque gains (docs/EQUATIONS.md "Computed torque")."""
    bandwidth_rad_s: float            # task-space loop: Kp = w^2, Kd = 2 zeta w, Ki = f w^3
    damping: float
    integral_fraction: float
    velocity_gain_per_s: float        # joint error -> commanded piston velocity
    force_bandwidth_rad_s: float      # each leg's force loop on its load cell, scheduled on its operating point
    velocity_filter_hz: float         # low-pass of the measured twist / velocity (the D term)

    @classmethod
    def of(cls, section: dict, prefix: str = "") -> ComputedTorqueGains:
        return cls(2 * math.pi * section[prefix + "bandwidth_hz"], section[prefix + "damping"],
                   section[prefix + "integral_fraction"], section[prefix + "velocity_gain_per_s"],
                   2 * math.pi * section[prefix + "force_bandwidth_hz"], section[prefix + "velocity_filter_hz"])


@dataclass(frozen=True)
class ControllerConfig:
    raw: dict                         # thesis units, as loaded
    # timing
    sync_window_fraction: float
    commit_room_s: float
    spin_s: float
    lockstep_timeout_s: float
    activation_timeout_s: float
    hold_cycles: int
    shutdown_hold_cycles: int
    shutdown_disable_cycles: int
    heartbeat_s: float
    heartbeat_timeout_s: float
    realtime_priority: int
    cpu_latency_us: int               # realtime: PM QoS wake-up latency asked of the CPUs (-1: none)
    cpu: int
    # actuator
    piston_area_m2: float             # A_A, the bore: PL = pA - alpha pB acts on it
    area_ratio: float                 # alpha = A_B / A_A
    stroke_m: float
    moving_mass_kg: float
    valve_full_scale_v: float
    encoder_resolution_m: float
    slide_mass_kg: float
    testbench_home_m: float
    testbench_park_m: float
    testbench_plausibility_spool: float   # the test bench's own motion window (fraction of full input) ...
    testbench_plausibility_cycles: int    # ... and length: its slide carries no static load
    guide_coulomb_n: float            # the test bench guide's friction (Table D.1, eq. D.3's gross
    guide_viscous_ns_m: float         # motion): eq. 6.5's Ffg in the friction identification
    test_force_gain_v_n: float        # HOST_TEST FORCE_SINE: P gain of the piston-force loop
    test_force_filter_hz: float       # ... and the cut-off of its low-pass on the measured F_p
    test_stroke_guard_m: float        # HOST_TEST VALVE_STEP: ends this close to an end stop
    hexapod_park_stroke_m: float
    hexapod_kp_factor: float          # every controller's Kp on the hexapod (see controller.toml)
    hexapod_ki_factor: float          # every controller's Ki on the hexapod
    hexapod_payload_kg: float         # carried at the platform's centre of mass (the dynamics' model)
    # estimation
    friction: np.ndarray              # LuGre vector of the seals (physics.lugre layout)
    observer_gain_per_s: float        # k of the friction observer (eq. 7.30)
    jerk_psd: float                   # m^2/s^5
    kalman_adaptive_gain: float
    kalman_velocity_ref_m_s: float
    rls_forgetting: float
    rls_filter_hz: float
    rls_filter_zeta: float
    rls_initial_kg: float
    rls_p0: float
    rls_p_max: float
    mass_max_kg: float
    differentiator_hz: float
    differentiator_zeta: float
    # control, gains in SI (V/m, V/(m s), V/Pa)
    pi_kp: float
    pi_ki: float
    saturation_v: float
    kpl_v_pa: float
    ki_scale: float
    table_position_m: np.ndarray      # (n_pos,)
    table_load_kg: np.ndarray         # (3,)
    table_kp: np.ndarray              # (3, n_pos) V/m
    table_ki: np.ndarray              # (3, n_pos) V/(m s), as printed (ki_scale applied by the schedule)
    feedforward_scale: float
    # computed torque (hexapod): task-space PID through the inverse dynamics, a valve map
    ct_hexapod: ComputedTorqueGains
    ct_testbench: ComputedTorqueGains
    ct_force_rate_floor: float        # N/s per unit spool: the force loops' schedule takes it no lower
    valve_map_force_n: np.ndarray     # (n_f,)
    valve_map_velocity_m_s: np.ndarray    # (n_v,)
    valve_map_spool: np.ndarray       # (n_f, n_v) steady-state spool, fraction of full input
    valve_map_pressure_a_pa: np.ndarray   # (n_f, n_v) the chamber pressures there
    valve_map_pressure_b_pa: np.ndarray
    # the actuators' hydraulic model and its residuals
    hydraulics: np.ndarray            # physics.hydraulics HP_* vector (the [actuator] stroke)
    supply_pressure_pa: float
    residuals_enabled: bool
    residual_gain: float              # chamber correction per cycle, fraction of the force error
    residual_filter_s: float
    residual_persistence: int
    residual_flow_spread: float       # relative
    residual_stiffness_n_m: float     # a leg's oil column in the thresholds (the median along the movements)
    residual_supply_legs: int
    load_cell_noise_n: float          # 1-sigma: the frozen load-cell check's limit follows from it
    spool_check: bool                 # the valves report their spool (LEG_STATE's SPOOL): judge it
    spool_floor: float                # the spool residual's floor, fraction of full input
    spool_lag_spread: float           # the spool's time constant known to within this, relative
    spool_persistence: int
    residual_leakage_spread: float    # relative: the leakage's and the stiffness's known spread
    residual_stiffness_spread: float
    pressure_noise_pa: float          # 1-sigma of the chamber transducers (LEG_PRESSURE's PA, PB)
    pressure_persistence: int         # samples beyond the prediction's threshold in a row: the leg is faulty
    # limits and supervisor
    stroke_margin_m: float
    velocity_max_m_s: float
    force_max_n: float
    tracking_error_max_m: float
    spool_max: float                  # fraction of full input
    missing_frames_fault: int
    e2e_errors_fault: int
    overruns_fault: int
    dk_failures_fault: int
    dk_tolerance_m: float
    dk_max_iterations: int
    singularity_ratio_min: float
    auto_enable: bool
    homing_speed_m_s: float
    homing_accel_time_s: float
    waypoint_queue: int
    waypoint_velocity_max_m_s: float
    waypoint_step_max_m: float
    waypoint_force_max_n: float
    waypoint_path_samples: int
    plausibility_spool: float         # fraction of full input
    plausibility_cycles: int
    plausibility_travel_m: float
    attitude_mismatch_rad: float      # encoders' DK attitude against the IMU's
    attitude_mismatch_samples: int
    controlled_stop_s: float          # hexapod: after a one-leg fault the others move this long (stopping.py)
    stall_fault_periods: float        # realtime: a SYNC this many periods after the previous one -> OVERRUN


def _schedule_tables(a: dict, source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    positions = np.array(a["table_position_mm"]) * MM
    loads = np.array(a["table_load_kg"])
    where = f"config {source}: [adaptive]"
    if len(positions) < 4 or np.any(np.diff(positions) <= 0):
        raise ConfigError(f"{where}.table_position_mm must hold >= 4 strictly increasing values")
    if len(loads) != len(SCHEDULE_LOADS) or np.any(np.diff(loads) <= 0) or loads[0] < 0:
        raise ConfigError(f"{where}.table_load_kg must hold 3 increasing non-negative masses, got {list(loads)}")
    kp = np.empty((3, len(positions)))
    ki = np.empty((3, len(positions)))
    for j, load in enumerate(SCHEDULE_LOADS):
        for name, out, scale in ((f"kp_{load}_v_mm", kp, 1.0 / MM), (f"ki_{load}_v_mm_s", ki, 1.0 / MM)):
            values = a[name]
            if len(values) != len(positions):
                raise ConfigError(f"{where}.{name} has {len(values)} values, table_position_mm has {len(positions)}")
            if min(values) < 0:
                raise ConfigError(f"{where}.{name} has a negative gain {min(values)}")
            out[j] = np.array(values) * scale
    return positions, loads, kp, ki


def _valve_map(vm: dict, source: str) -> tuple[np.ndarray, ...]:
    where = f"config {source}: [valve_map]"
    forces, velocities = np.array(vm["force_n"], dtype=float), np.array(vm["velocity_mm_s"], dtype=float) * MM
    for name, axis in (("force_n", forces), ("velocity_mm_s", velocities)):
        if axis.ndim != 1 or len(axis) < 2 or np.any(np.diff(axis) <= 0) or not np.all(np.isfinite(axis)):
            raise ConfigError(f"{where}.{name} must hold >= 2 strictly increasing numbers")
    tables = []
    for name, scale, low, high in (("spool_pct", 0.01, -1.0, 1.0), ("pressure_a_bar", BAR, -BAR, 1e3 * BAR),
                                   ("pressure_b_bar", BAR, -BAR, 1e3 * BAR)):
        try:
            table = np.array(vm[name], dtype=float) * scale
        except ValueError:
            raise ConfigError(f"{where}.{name} must be a table of numbers, one row per force") from None
        if table.shape != (len(forces), len(velocities)):
            raise ConfigError(f"{where}.{name} is {'x'.join(map(str, table.shape))}, force_n x velocity_mm_s "
                              f"is {len(forces)}x{len(velocities)}")
        if not np.all((table >= low) & (table <= high)):
            raise ConfigError(f"{where}.{name} holds a value outside [{low / scale:g}, {high / scale:g}] "
                              f"(or not a number)")
        tables.append(np.ascontiguousarray(table))
    return (forces, velocities, *tables)


def build(raw: dict, source: str = "config") -> ControllerConfig:
    t, a, tb, f, k, m = (raw[s] for s in ("timing", "actuator", "testbench", "friction", "kalman", "mass_estimator"))
    ident = raw["identification"]
    lp, pi, ad, lim, sv = (raw[s] for s in ("load_pressure", "pi", "adaptive", "limits", "supervisor"))
    if a["rod_radius_mm"] >= a["bore_radius_mm"]:
        raise ConfigError(f"config {source}: [actuator].rod_radius_mm = {a['rod_radius_mm']} must be smaller "
                          f"than bore_radius_mm = {a['bore_radius_mm']}")
    if m["covariance_initial"] > m["covariance_max"]:
        raise ConfigError(f"config {source}: [mass_estimator].covariance_initial = {m['covariance_initial']} "
                          f"exceeds covariance_max = {m['covariance_max']}")
    positions, loads, kp, ki = _schedule_tables(ad, source)
    ct = raw["computed_torque"]
    map_forces, map_velocities, map_spool, map_pa, map_pb = _valve_map(raw["valve_map"], source)
    hm, rs = raw["hydraulic_model"], raw["residuals"]
    if hm["tank_pressure_bar"] >= hm["supply_pressure_bar"]:
        raise ConfigError(f"config {source}: [hydraulic_model].tank_pressure_bar = {hm['tank_pressure_bar']} must "
                          f"be below supply_pressure_bar = {hm['supply_pressure_bar']}")
    hydraulics = hy.pack({**a, "tank_pressure_bar": hm["tank_pressure_bar"]}, hm, hm)
    area, ratio = cylinder_areas(a["bore_radius_mm"] * MM, a["rod_radius_mm"] * MM)
    try:
        friction = lugre.from_table(f)
    except ValueError as error:
        raise ConfigError(f"config {source}: [friction]: {error}") from None
    return ControllerConfig(
        raw=raw,
        sync_window_fraction=t["sync_window_fraction"], spin_s=t["spin_us"] * 1e-6,
        commit_room_s=t["commit_room_us"] * 1e-6,
        lockstep_timeout_s=t["lockstep_timeout_ms"] * 1e-3, activation_timeout_s=t["activation_timeout_s"],
        hold_cycles=t["hold_cycles"], shutdown_hold_cycles=t["shutdown_hold_cycles"],
        shutdown_disable_cycles=t["shutdown_disable_cycles"], heartbeat_s=t["heartbeat_ms"] * 1e-3,
        heartbeat_timeout_s=t["heartbeat_timeout_ms"] * 1e-3,
        realtime_priority=t["realtime_priority"], cpu=t["cpu"], cpu_latency_us=t["cpu_latency_us"],
        piston_area_m2=area, area_ratio=ratio, stroke_m=a["stroke_mm"] * MM, moving_mass_kg=a["moving_mass_kg"],
        valve_full_scale_v=a["valve_full_scale_v"], encoder_resolution_m=a["encoder_resolution_mm"] * MM,
        slide_mass_kg=tb["slide_mass_kg"], testbench_home_m=tb["home_mm"] * MM, testbench_park_m=tb["park_mm"] * MM,
        testbench_plausibility_spool=tb["plausibility_spool_pct"] / 100.0,
        testbench_plausibility_cycles=tb["plausibility_cycles"],
        guide_coulomb_n=tb["guide_coulomb_n"], guide_viscous_ns_m=tb["guide_viscous_ns_mm"] / MM,
        test_force_gain_v_n=ident["force_gain_v_n"],
        test_force_filter_hz=ident["force_filter_hz"], test_stroke_guard_m=ident["stroke_guard_mm"] * MM,
        hexapod_park_stroke_m=raw["hexapod"]["park_stroke_mm"] * MM, hexapod_kp_factor=raw["hexapod"]["kp_factor"],
        hexapod_ki_factor=raw["hexapod"]["ki_factor"], hexapod_payload_kg=raw["hexapod"]["payload_kg"],
        friction=friction, observer_gain_per_s=f["observer_gain_per_s"], jerk_psd=k["jerk_psd_mm2_s5"] * MM ** 2,
        kalman_adaptive_gain=k["adaptive_gain"],
        kalman_velocity_ref_m_s=k["adaptive_velocity_ref_mm_s"] * MM,
        rls_forgetting=m["forgetting"], rls_filter_hz=m["filter_hz"], rls_filter_zeta=m["filter_zeta"],
        rls_initial_kg=m["initial_kg"], rls_p0=m["covariance_initial"], rls_p_max=m["covariance_max"],
        mass_max_kg=m["mass_max_kg"], differentiator_hz=lp["differentiator_hz"],
        differentiator_zeta=lp["differentiator_zeta"],
        pi_kp=pi["kp_v_mm"] / MM, pi_ki=pi["ki_v_mm_s"] / MM, saturation_v=pi["saturation_v"],
        kpl_v_pa=ad["kpl_v_bar"] / BAR, ki_scale=ad["ki_scale"], table_position_m=positions, table_load_kg=loads,
        table_kp=kp, table_ki=ki, feedforward_scale=raw["model_based"]["feedforward_scale"],
        ct_hexapod=ComputedTorqueGains.of(ct), ct_testbench=ComputedTorqueGains.of(ct, "testbench_"),
        ct_force_rate_floor=ct["force_rate_floor_n_s_pct"] * 100.0,

        valve_map_force_n=map_forces, valve_map_velocity_m_s=map_velocities, valve_map_spool=map_spool,
        valve_map_pressure_a_pa=map_pa, valve_map_pressure_b_pa=map_pb,
        hydraulics=hydraulics, supply_pressure_pa=hm["supply_pressure_bar"] * BAR, residuals_enabled=rs["enabled"],
        residual_gain=rs["correction_gain"], residual_filter_s=rs["filter_ms"] * 1e-3,
        residual_persistence=rs["persistence_cycles"], residual_flow_spread=rs["flow_spread_pct"] / 100.0,
        residual_stiffness_n_m=rs["column_stiffness_n_mm"] / MM,
        residual_supply_legs=rs["supply_legs"], load_cell_noise_n=rs["load_cell_noise_n"],
        spool_check=rs["spool_check"], spool_floor=rs["spool_floor_pct"] / 100.0,
        spool_lag_spread=rs["spool_lag_spread_pct"] / 100.0, spool_persistence=rs["spool_persistence_cycles"],
        residual_leakage_spread=rs["leakage_spread_pct"] / 100.0,
        residual_stiffness_spread=rs["stiffness_spread_pct"] / 100.0, pressure_noise_pa=rs["pressure_noise_bar"] * BAR,
        pressure_persistence=rs["pressure_persistence_samples"],
        stroke_margin_m=lim["stroke_margin_mm"] * MM, velocity_max_m_s=lim["velocity_max_mm_s"] * MM,
        force_max_n=lim["force_max_n"], tracking_error_max_m=lim["tracking_error_max_mm"] * MM,
        spool_max=lim["spool_max_pct"] / 100.0,
        missing_frames_fault=sv["missing_frames_fault"], e2e_errors_fault=sv["e2e_errors_fault"],
        overruns_fault=sv["overruns_fault"], dk_failures_fault=sv["dk_failures_fault"],
        dk_tolerance_m=sv["dk_tolerance_um"] * 1e-6, dk_max_iterations=sv["dk_max_iterations"],
        singularity_ratio_min=sv["singularity_ratio_min"], auto_enable=sv["auto_enable"],
        homing_speed_m_s=sv["homing_speed_mm_s"] * MM, homing_accel_time_s=sv["homing_accel_time_s"],
        waypoint_queue=sv["waypoint_queue"], waypoint_velocity_max_m_s=sv["waypoint_velocity_max_mm_s"] * MM,
        waypoint_step_max_m=sv["waypoint_step_max_mm"] * MM,
        waypoint_force_max_n=sv["waypoint_force_max_n"], waypoint_path_samples=sv["waypoint_path_samples"],
        plausibility_spool=sv["plausibility_spool_pct"] / 100.0, plausibility_cycles=sv["plausibility_cycles"],
        plausibility_travel_m=sv["plausibility_travel_mm"] * MM,
        attitude_mismatch_rad=math.radians(sv["attitude_mismatch_deg"]),
        attitude_mismatch_samples=sv["attitude_mismatch_samples"], controlled_stop_s=sv["controlled_stop_ms"] * 1e-3,
        stall_fault_periods=t["stall_fault_periods"],
    )


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> ControllerConfig:
    raw = load_layered(RANGES, default_config_path(), path, overrides, ConfigError)
    return build(raw, str(path) if path is not None else str(default_config_path()))
