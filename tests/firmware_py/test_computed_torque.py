"""The computed-torque controller: its kernels against SciPy as the oracle, its packaged
plant data against what `hydrapod design computed-torque` derives from the emulator, its
outputs at rest on the hexapod and on the test bench, and where it may run."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial.transform import Rotation

from firmware_py.config import ConfigError, load_config
from firmware_py.controller import Controller
from firmware_py.mechanics.geometry import default_geometry
from firmware_py.motion_control.computed_torque import (
    STIFF_COUNT,
    STIFF_FIRST,
    ComputedTorque,
    LegComputedTorque,
    beyond_force_range,
    pose_error_into,
    valve_map_eval,
)
from firmware_py.motion_control.joint_space import COMPUTED_TORQUE, CONTROLLER_NAMES
from firmware_py.rig_model import HexapodModel
from firmware_py.supervision.capacity import leg_capacity
from hil.cli import main
from protocol.enums import Ack, Command
from tests.support.loops import command

PERIOD_S = 0.002


@pytest.fixture(scope="module")
def cfg():
    return load_config()


@pytest.fixture(scope="module")
def held_cfg():
    """The stiff integral's velocity share kept at rest for the tests' span (its fading at rest
    has its own test)."""
    return load_config(overrides={"computed_torque": {"stiff_rest_hold_s": 100.0}})


def test_the_valve_map_interpolates_as_scipy_does_and_holds_its_edges(cfg):
    f, v, spool = cfg.valve_map.force_n, cfg.valve_map.velocity_m_s, cfg.valve_map.spool
    oracle = RegularGridInterpolator((f, v), spool)
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(f[0] - 80, f[-1] + 80, 2000), rng.uniform(v[0] - 0.2, v[-1] + 0.2, 2000)])
    clamped = np.column_stack([np.clip(points[:, 0], f[0], f[-1]), np.clip(points[:, 1], v[0], v[-1])])
    ours = np.array([valve_map_eval(f, v, spool, a, b) for a, b in points])
    np.testing.assert_allclose(ours, oracle(clamped), atol=1e-12)


def test_the_pose_error_is_scipys_rotation_vector():
    rng = np.random.default_rng(4)
    out = np.empty(6)
    for _ in range(200):
        r_ref, r = Rotation.random(random_state=rng), Rotation.random(random_state=rng)
        p_ref, p = rng.normal(size=3), rng.normal(size=3)
        reference = np.r_[p_ref, r_ref.as_quat(scalar_first=True)]
        measured = np.r_[p, r.as_quat(scalar_first=True)]
        pose_error_into(reference, measured, out)
        np.testing.assert_allclose(out[:3], p_ref - p, atol=1e-12)
        np.testing.assert_allclose(out[3:], (r_ref * r.inv()).as_rotvec(), atol=1e-9)


def test_the_packaged_plant_data_is_what_the_design_command_derives(cfg, tmp_path, capsys):
    """`design computed-torque` writes a config the controller loads, and the packaged
    [valve_map] (spool and chamber pressures) is its output from the emulator's model, not
    set by hand."""
    path = tmp_path / "ct.toml"
    assert main(["design", "computed-torque", "--out", str(path), "--bandwidth-hz", "2.5", "--json"]) == 0
    derived = load_config(path)
    assert derived.computed_torque.hexapod.bandwidth_rad_s == pytest.approx(2 * np.pi * 2.5)
    np.testing.assert_allclose(cfg.valve_map.spool, derived.valve_map.spool, atol=5e-7)
    for ours, theirs in ((cfg.valve_map.pressure_a_pa, derived.valve_map.pressure_a_pa),
                         (cfg.valve_map.pressure_b_pa, derived.valve_map.pressure_b_pa)):
        np.testing.assert_allclose(ours, theirs, atol=6.0)                 # the file's 0.0001 bar
    np.testing.assert_array_equal(cfg.valve_map.force_n, derived.valve_map.force_n)
    np.testing.assert_allclose(cfg.valve_map.velocity_m_s, derived.valve_map.velocity_m_s, atol=1e-12)


def test_the_residuals_column_stiffness_is_the_median_along_the_movements(cfg):
    """[residuals] column_stiffness_n_mm is the emulated legs' median oil-column stiffness
    over every waypoint of both movements (`design modes --along`), not a chosen number."""
    from hil.design.modes import modal_model, movement_waypoints
    from plant_emulator.params import load_config as load_emulator_config
    emulator = load_emulator_config()
    values = [modal_model(emulator, point).stiffness_n_m for points in movement_waypoints().values()
              for point in points]
    assert cfg.residuals.column_stiffness_n_m == pytest.approx(float(np.median(np.concatenate(values))), rel=1e-3)


def test_the_force_loop_has_the_same_bandwidth_wherever_the_leg_stands(cfg):
    """The scheduled gain k_F = w_F / (dF'/dx) at a leg's operating point: with the leg's
    oil-column stiffness K and flow gain k_q of the emulator's linearisation at that point
    (`design modes`, finite differences of the chamber law: the oracle), K k_q k_F = w_F at
    home and at the circle's start, where K and k_q differ by 2-6x."""
    from hil.design.modes import modal_model
    from plant_emulator.params import load_config as load_emulator_config
    emulator = load_emulator_config()
    ct = ComputedTorque(cfg, default_geometry(), PERIOD_S)
    for pose in ((0.0, 0.0, 0.5835), (0.2, 0.0, 0.631)):
        model = modal_model(emulator, np.array(pose))
        zeros = np.zeros(6)
        ct.spool_commands(model.static_force_n, model.static_force_n, model.static_force_n, model.static_force_n,
                          model.static_force_n, zeros, zeros, model.strokes_m)
        np.testing.assert_allclose(ct.stiffness, model.stiffness_n_m, rtol=0.05)
        bandwidth = ct.stiffness * model.flow_gain_m_s * ct.force_gain
        # the reference at rest: its resting bandwidth (while it moves, the moving one)
        np.testing.assert_allclose(bandwidth, cfg.computed_torque.hexapod.force_bandwidth_rest_rad_s, rtol=0.05)


def test_a_map_made_at_another_supply_says_so_and_opens_less(cfg, tmp_path):
    """`--supply-bar 40`: the map of a stiffer supply (less spool for the same force and
    velocity, by about sqrt(25 / 40) from the orifice law; the grid's edges beyond the 25 bar
    supply's reach differ) and the controller's model supply with it."""
    path = tmp_path / "ct40.toml"
    assert main(["design", "computed-torque", "--out", str(path), "--supply-bar", "40", "--samples", "0",
                 "--json"]) == 0
    derived = load_config(path)
    assert derived.hydraulic_model.supply_pressure_pa == pytest.approx(40e5)
    moving = np.abs(cfg.valve_map.velocity_m_s) >= 0.2            # where the flow, not the lap, sets it
    ratio = np.abs(derived.valve_map.spool[:, moving]) / np.abs(cfg.valve_map.spool[:, moving])
    assert np.percentile(ratio, 90) < 1.0 and np.median(ratio) == pytest.approx(np.sqrt(25 / 40), rel=0.1)


def test_at_rest_on_the_reference_the_valves_get_the_maps_holding_spool(cfg):
    """Measured pose = reference, nothing moving, load cells reading the model's forces: the
    spool is the map's at those forces and zero velocity (no feedback term acts)."""
    rig = HexapodModel(cfg, PERIOD_S)
    platform, ct, home, zeros = rig.platform, rig.computed_torque, rig.home_strokes, np.zeros(6)
    platform.estimate(home)
    platform.reset_reference(home)
    assert platform.reference_forces(home, zeros)
    force = platform.force_n.copy()
    for _ in range(3):
        assert ct.update(platform, home, home, zeros, zeros, zeros, zeros, force)
        force[:] = ct.force_cmd
    np.testing.assert_allclose(ct.error, 0.0, atol=1e-9)
    expected = [valve_map_eval(cfg.valve_map.force_n, cfg.valve_map.velocity_m_s, cfg.valve_map.spool, f, 0.0)
                for f in ct.force_cmd]
    np.testing.assert_allclose(ct.spool_cmd, expected, atol=1e-6)
    np.testing.assert_allclose(ct.force_cmd, platform.force_n, rtol=1e-6, atol=1e-6)      # a_cmd = 0 at rest


def _holding_off(cfg, offset_m, cycles: int):
    """The hexapod's law holding home while the platform stands `offset_m` (base frame) from it,
    the load cells reading the model's forces: (its law, the platform model, the legs' errors,
    updates so far) after each update."""
    rig = HexapodModel(cfg, PERIOD_S)
    platform, ct, home, zeros = rig.platform, rig.computed_torque, rig.home_strokes, np.zeros(6)
    platform.reset_reference(home)
    assert platform.reference_forces(home, zeros)
    platform.update_measured_kinematics(platform.dk.home[0:3] + np.asarray(offset_m), platform.dk.home[3:7])
    strokes = platform.lengths - rig.geometry.leg_min_m
    platform.estimate(strokes)
    for k in range(1, cycles + 1):
        assert ct.update(platform, home, strokes, zeros, home - strokes, zeros, zeros, platform.force_n)
        yield ct, platform, home - strokes, k


def _held_off(cfg, offset_m, cycles: int):
    """As `_holding_off`, after `cycles` updates: (its law, the platform model, the legs' errors)."""
    *held, _ = list(_holding_off(cfg, offset_m, cycles))[-1]
    return held


def test_a_height_error_integrates_into_every_legs_commanded_velocity(held_cfg):
    """The PID's integral in the stiff directions also drives the legs' velocity: the platform
    held 1 mm low for 100 cycles integrates 0.2 mm s in z (nothing in roll or pitch), and each
    leg's equivalent error carries J_s K_s int(e_s) / lambda (the integral up to the cycle
    before) beside its own."""
    ct, platform, joint_error = _held_off(held_cfg, (0.0, 0.0, -1e-3), 100)
    stiff = slice(STIFF_FIRST, STIFF_FIRST + STIFF_COUNT)
    assert ct.integral[STIFF_FIRST] == pytest.approx(100 * PERIOD_S * 1e-3, rel=1e-3)
    np.testing.assert_allclose(ct.integral[STIFF_FIRST + 1:STIFF_FIRST + STIFF_COUNT], 0.0, atol=1e-9)
    gain = held_cfg.computed_torque.stiff_integral_per_s2 / held_cfg.computed_torque.velocity_gain_per_s
    used = ct.integral[stiff] - PERIOD_S * ct.error[stiff]          # before this cycle's step
    stiff = platform.jacobian[:, stiff] @ used
    np.testing.assert_allclose(ct.velocity_error, joint_error + gain * stiff, rtol=1e-9, atol=1e-12)
    assert np.all(ct.velocity_error > joint_error)          # every leg asked up, more than its error alone


def test_a_sideways_error_is_not_a_stiff_one_and_reset_clears_it(held_cfg):
    """x is not a stiff direction (the PID's force moves it): its integral grows, the legs'
    velocity gets none of it; a height error's share is gone after `reset`."""
    ct, _, joint_error = _held_off(held_cfg, (1e-3, 0.0, 0.0), 100)
    assert ct.integral[0] == pytest.approx(-100 * PERIOD_S * 1e-3, rel=1e-3)     # reference - measured
    np.testing.assert_allclose(ct.integral[STIFF_FIRST:STIFF_FIRST + STIFF_COUNT], 0.0, atol=1e-9)
    np.testing.assert_allclose(ct.velocity_error, joint_error, atol=1e-9)
    ct, _, _ = _held_off(held_cfg, (0.0, 0.0, -1e-3), 10)
    ct.reset()
    assert not np.any(ct.integral)


def test_the_integral_stops_while_a_valve_saturates(held_cfg):
    """Conditional integration: load cells 2 kN off drive every valve to its limit, and the
    integral, the stiff directions' velocity share with it, holds."""
    ct, platform, joint_error = _held_off(held_cfg, (0.0, 0.0, -1e-3), 10)
    held = ct.integral.copy()
    zeros, home = np.zeros(6), platform.ref_lengths - platform.leg_min_m
    assert ct.update(platform, home, home - joint_error, zeros, joint_error, zeros, zeros, platform.force_n - 2000.0)
    assert np.max(np.abs(ct.spool_cmd)) == pytest.approx(held_cfg.limits.spool_max)
    np.testing.assert_array_equal(ct.integral, held)


def test_the_force_range_check_reads_the_capacity_table_as_numpy_does(cfg):
    """`beyond_force_range` against the check's own table read by np.interp
    (`LegCapacity.utilisation`): a leg beyond `share` of its range is beyond; at r times the
    supply, r F(v / sqrt(r)) (the orifices' similarity)."""
    capacity = leg_capacity(cfg)
    grid, push, pull = capacity.velocities_m_s, capacity.push_n, capacity.pull_n
    rng = np.random.default_rng(5)
    ones = np.ones(1)
    for _ in range(2000):
        force, velocity = rng.uniform(-400.0, 400.0, 1), rng.uniform(-0.6, 0.6, 1)
        share = rng.uniform(0.5, 2.0)
        ours = beyond_force_range(force, velocity, ones, grid, push, pull, share)
        assert ours == bool(capacity.utilisation(force, velocity)[0] > share), (force, velocity, share)
    # at 1.44 x the supply, at 0.12 m/s: the range at 0.1 m/s, 1.44 x
    r = np.array([1.44])
    push_at, _ = capacity.limits(np.array([0.1]))
    assert not beyond_force_range(np.array([0.99 * 1.44 * push_at[0]]), np.array([0.12]), r, grid, push, pull, 1.0)
    assert beyond_force_range(np.array([1.01 * 1.44 * push_at[0]]), np.array([0.12]), r, grid, push, pull, 1.0)


def test_the_integral_stops_while_a_leg_is_asked_beyond_its_range(held_cfg):
    """Conditional integration at a leg's force limit: held 1 mm aside, with the valves inside
    their range, x integrates; asked beyond a share no leg holding the platform stays under
    (1 %), it holds (the `windup_capacity_pct` of the packaged 150 %)."""
    free, _, _ = _held_off(held_cfg, (1e-3, 0.0, 0.0), 20)
    assert np.max(np.abs(free.spool_cmd)) < held_cfg.limits.spool_max
    assert free.integral[0] == pytest.approx(-20 * PERIOD_S * 1e-3, rel=1e-3)
    tight = load_config(overrides={"computed_torque": {"stiff_rest_hold_s": 100.0, "windup_capacity_pct": 1.0}})
    held, _, _ = _held_off(tight, (1e-3, 0.0, 0.0), 20)
    assert np.max(np.abs(held.spool_cmd)) < tight.limits.spool_max
    assert not np.any(held.integral)


def test_at_rest_the_velocity_share_fades_and_the_integral_stays(cfg):
    """Held 1 mm low with the reference at rest: for stiff_rest_hold_s the velocity's share is
    the whole integral; then its origin follows the integral (a first-order lag of time
    constant tau = stiff_rest_unwind_s), so the share settles at tau x the error, while the
    integral, the force's share, keeps growing."""
    gains = cfg.computed_torque
    hold = round(gains.stiff_rest_hold_s / PERIOD_S)
    alpha = 1.0 - np.exp(-PERIOD_S / gains.stiff_rest_unwind_s)
    origin, cycles = 0.0, 0
    for ct, _, _, cycles in _holding_off(cfg, (0.0, 0.0, -1e-3), hold + 400):
        if cycles < hold:
            assert ct.stiff_origin[0] == 0.0
        else:
            origin += alpha * (ct.integral[STIFF_FIRST] - origin)
            assert ct.stiff_origin[0] == pytest.approx(origin, rel=1e-9)
    assert ct.integral[STIFF_FIRST] == pytest.approx(cycles * PERIOD_S * 1e-3, rel=1e-3)
    share = ct.integral[STIFF_FIRST] - ct.stiff_origin[0]
    assert share == pytest.approx(gains.stiff_rest_unwind_s * 1e-3, rel=0.05)


def test_the_twist_comes_from_the_legs_positions_backward_difference(cfg):
    """The hexapod's twist is J^-1 of the legs' position differences over one period (the
    Kalman filters' velocity passed beside it is not used): a 1 mm/s climb of every leg, the
    platform at home, gives J^-1 of it, as numpy solves it."""
    rig = HexapodModel(cfg, PERIOD_S)
    platform, ct, home, zeros = rig.platform, rig.computed_torque, rig.home_strokes, np.zeros(6)
    platform.estimate(home)
    platform.reset_reference(home)
    assert platform.reference_forces(home, zeros)
    assert ct.update(platform, home, home, np.full(6, 9.0), zeros, zeros, zeros, platform.force_n)
    np.testing.assert_array_equal(ct.twist_raw, 0.0)          # the first cycle: no difference yet
    climbed = home + 1e-3 * PERIOD_S
    assert ct.update(platform, home, climbed, np.full(6, 9.0), zeros, zeros, zeros, platform.force_n)
    np.testing.assert_allclose(ct.position_rate, 1e-3, rtol=1e-9)
    np.testing.assert_allclose(ct.twist_raw, np.linalg.solve(platform.jacobian, np.full(6, 1e-3)), rtol=1e-9,
                               atol=1e-15)


def test_a_stiff_integral_without_the_velocity_loop_is_refused(cfg):
    with pytest.raises(ConfigError, match="stiff_integral_per_s2"):
        load_config(overrides={"computed_torque": {"velocity_gain_per_s": 0.0}})


@pytest.mark.parametrize("rig", ["testbench", "hexapod"])
def test_computed_torque_is_selectable_on_both_rigs(cfg, rig):
    ctl = Controller(cfg, rig, PERIOD_S, CONTROLLER_NAMES["pi"])
    ctl.activated(False)
    assert command(ctl, Command.SELECT_CONTROLLER, COMPUTED_TORQUE) is Ack.ACCEPTED
    assert ctl.status.kind == COMPUTED_TORQUE


def test_a_law_selected_again_starts_from_rest_not_from_its_last_session(cfg):
    """Computed torque, deselected with its integral wound up and selected again minutes
    later: its integral starts from zero (a stale integral would push the stiff directions'
    velocity from the first cycle)."""
    from hil.in_process import InProcessLoop
    from plant_emulator.params import load_config as load_emulator_config
    loop = InProcessLoop(cfg, load_emulator_config(), "computed-torque")
    loop.activate(50)
    ct = loop.ctl.rig.computed_torque
    ct.integral[:] = 0.01                                  # as after a long lag
    assert loop.command(Command.SELECT_CONTROLLER, CONTROLLER_NAMES["pi"]) is Ack.ACCEPTED
    loop.cycles(5)
    np.testing.assert_array_equal(ct.integral, 0.01)       # not its turn: untouched
    assert loop.command(Command.SELECT_CONTROLLER, COMPUTED_TORQUE) is Ack.ACCEPTED
    assert np.max(np.abs(ct.integral)) < 1e-5              # one cycle's error at most


def bench_spool(cfg, load_n: float, below_m: float = 0.0, cycles: int = 5) -> tuple[float, LegComputedTorque]:
    """The test bench's law holding its reference at home (the encoder `below_m` under it), the
    load cell reading `load_n`: its spool."""
    ct = LegComputedTorque(cfg, 1, PERIOD_S)
    home, zero = np.full(1, cfg.testbench.home_m), np.zeros(1)
    for _ in range(cycles):
        assert ct.update(None, home, home - below_m, zero, np.full(1, below_m), zero, zero, np.full(1, load_n))
    return float(ct.spool_cmd[0]), ct


def test_the_test_benchs_valve_at_rest_gets_the_maps_spool_for_load_and_rod(cfg):
    """On the reference at rest: the map's spool at zero velocity for the load cell's force
    plus the rod's weight (the seals' friction is 0 at rest, the force loop has no a_cmd)."""
    load_n = 60.0
    spool, leg = bench_spool(cfg, load_n)
    piston_n = load_n + cfg.actuator.moving_mass_kg * 9.81
    assert leg.force_map[0] == pytest.approx(piston_n, abs=1e-6)
    expected = valve_map_eval(cfg.valve_map.force_n, cfg.valve_map.velocity_m_s, cfg.valve_map.spool, piston_n, 0.0)
    assert spool == pytest.approx(expected, abs=1e-6)


def test_the_test_benchs_leg_below_its_reference_opens_the_valve_upwards(cfg):
    """The encoder 1 mm below the held reference: the velocity loop asks lambda x 1 mm/s up
    through the map, and the PID's acceleration adds force: the spool opens beyond the
    holding one, and more with the larger error."""
    holding, _ = bench_spool(cfg, 60.0, cycles=1)
    openings = [bench_spool(cfg, 60.0, below_m, cycles=1)[0] for below_m in (1e-3, 2e-3)]
    assert holding < openings[0] < openings[1]
