"""Plant emulator physics: hydraulics, LuGre friction, rigs, calibration, valve state machine."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.design import calibration
from physics import hydraulics as hy
from physics.constants import GRAVITY_M_S2
from physics.lugre import force_split as lugre_split
from physics.lugre import steady_friction
from physics.lugre import z_step as lugre_z_step
from plant_emulator.params import ConfigError, load_config
from plant_emulator.rigs import HexapodRig, TestbenchRig
from plant_emulator.valve_node import FaultReason, ValveDriver, ValveState

PERIOD = 0.002
# Table 6.1 (thesis units), typed here independently of the package's data file.
TABLE_6_1 = {"pos": (12.1994, 10.6468, 10.0, 0.1316), "neg": (-15.0, -5.3903, -20.0, 0.0753)}


def table_6_1_force(v_mm_s: float) -> float:
    a0, a1, vs, s2 = TABLE_6_1["pos" if v_mm_s > 0 else "neg"]
    return a0 + a1 * math.exp(-(v_mm_s / vs) ** 2) + s2 * v_mm_s


@pytest.fixture(scope="module")
def cfg():
    return load_config()


def run(rig, seconds):
    for _ in range(round(seconds / PERIOD)):
        rig.advance(PERIOD)


def _edges(spool, pa, pb, ps, hp):
    """eq. 4.4-4.6 with underlap, every edge evaluated by eq. 4.2 as written (NumPy's power)."""
    lam, pt, kv = hp[hy.HP_LAMINAR], hp[hy.HP_TANK], hp[hy.HP_KV]
    root = lambda dp: dp / np.power(dp * dp + lam * lam, 0.25)                          # noqa: E731
    slope = lambda dp: (0.5 * dp * dp + lam * lam) / np.power(dp * dp + lam * lam, 1.25)  # noqa: E731
    a_pa, a_at = max(spool + hp[hy.HP_LAP_P], 0.0), max(hp[hy.HP_LAP_T] - spool, 0.0)
    a_pb, a_bt = max(hp[hy.HP_LAP_P] - spool, 0.0), max(spool + hp[hy.HP_LAP_T], 0.0)
    qa, qb = kv * (a_pa * root(ps - pa) - a_at * root(pa - pt)), kv * (a_pb * root(ps - pb) - a_bt * root(pb - pt))
    dqa = -kv * (a_pa * slope(ps - pa) + a_at * slope(pa - pt))
    dqb = -kv * (a_pb * slope(ps - pb) + a_bt * slope(pb - pt))
    drawn = kv * (a_pa * root(ps - pa) + a_pb * root(ps - pb))
    return qa, qb, dqa, dqb, drawn, kv * (a_pa * slope(ps - pa) + a_pb * slope(ps - pb))


@settings(max_examples=300, deadline=None)
@given(spool=st.floats(-1.0, 1.0), pa=st.floats(-0.9e5, 60e5), pb=st.floats(-0.9e5, 60e5), ps=st.floats(1e5, 40e5))
def test_the_valve_kernels_are_eq_4_2_on_every_edge(cfg, spool, pa, pb, ps):
    """The kernels take the fourth root as two square roots and skip closed edges (for speed):
    the flows, their slopes and the supply's draw are eq. 4.2-4.6 as written, to rounding."""
    hp = cfg.hp
    expected = _edges(spool, pa, pb, ps, hp)
    got = (*hy.valve_flows(spool, pa, pb, ps, hp), *hy.supply_flow(spool, pa, pb, ps, hp, 1.0))
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-18)
    dp, h = pa - pb, 1e-3 * hp[hy.HP_LAMINAR]
    numeric = (hy.orifice_root(dp + h, hp[hy.HP_LAMINAR]) - hy.orifice_root(dp - h, hp[hy.HP_LAMINAR])) / (2 * h)
    assert hy.orifice_root_and_slope(dp, hp[hy.HP_LAMINAR])[1] == pytest.approx(numeric, rel=1e-5)


@pytest.mark.parametrize("index", [1.0, 1.4])
def test_the_bulk_modulus_is_its_series_law_isothermal_or_not(cfg, index):
    """Oil with polytropic air and the hose wall in series (the isothermal case takes no power)."""
    hp = cfg.hp.copy()
    hp[hy.HP_POLY_N] = index
    for p in (-0.5e5, 0.0, 3e5, 25e5, 200e5):
        p_abs = p + 101325.0
        eps = hp[hy.HP_AIR0] * (101325.0 / p_abs) ** (1.0 / index)
        compliance = (1.0 / hp[hy.HP_BETA_OIL] + eps / (index * p_abs)) / (1.0 + eps) + 1.0 / hp[hy.HP_BETA_WALL]
        assert hy.bulk_modulus(p, hp) == pytest.approx(1.0 / compliance, rel=1e-14)


def test_the_spool_lag_over_many_steps_is_its_exact_step(cfg):
    """`spool_lag` with one `spool_decay` is `spool_step`, and both the exact first-order lag
    toward the command saturated at full input."""
    hp, h = cfg.hp, PERIOD / 8
    stepped = lagged = exact = 0.1
    for command in (0.8, 0.8, -1.5, 0.0, 1.7):
        stepped = hy.spool_step(stepped, command, h, hp)
        lagged = hy.spool_lag(lagged, command, hy.spool_decay(h, hp))
        target = min(max(command, -1.0), 1.0)
        exact = target + (exact - target) * math.exp(-h / hp[hy.HP_TAU_SPOOL])
        assert stepped == lagged == pytest.approx(exact, rel=1e-14, abs=1e-16)


@pytest.mark.parametrize("load", [0.0, 6.0])
def test_open_loop_step_gives_constant_velocity(cfg, load):
    """Fig. 6.3: a constant valve input moves the piston at constant velocity after ~0.5 s."""
    rig = TestbenchRig(cfg, load, start_mm=50.0)
    run(rig, 0.2)
    rig.command[0] = 0.5 / cfg.actuator.valve_full_scale_v * (1 if load == 0 else 2)    # 0.5 V, 1 V
    positions = []
    for _ in range(500):
        rig.advance(PERIOD)
        positions.append(rig.state[0, hy.S_Y])
    velocity = np.diff(positions)[250:] / PERIOD
    assert velocity.mean() > 0.02                               # moving up, > 20 mm/s
    assert velocity.std() < 0.02 * velocity.mean()              # constant within 2 %


def test_steady_friction_follows_table_6_1(cfg):
    """Seal friction measured on the rig at constant velocity matches Table 6.1's map."""
    for volts in (0.3, 0.5, 1.0, -0.2, -0.5, -1.0):
        rig = TestbenchRig(cfg, 0.0, start_mm=150.0)
        run(rig, 0.1)
        rig.command[0] = volts / cfg.actuator.valve_full_scale_v
        speeds, forces = [], []
        for k in range(400):
            y0 = rig.state[0, hy.S_Y]
            rig.advance(PERIOD)
            if k >= 250:
                speeds.append((rig.state[0, hy.S_Y] - y0) / PERIOD)
                forces.append(rig.seal_friction_n)
        v_mm_s = 1e3 * float(np.mean(speeds))
        assert abs(v_mm_s) > 5.0, volts
        expected = table_6_1_force(v_mm_s)
        assert float(np.mean(forces)) == pytest.approx(expected, rel=0.10), (volts, v_mm_s)


def _free_fall_drop_m(cfg, load_kg, seconds=0.2, h=1e-5):
    """Appendix D's experiment on the emulator's guide: the slide plus load released from rest,
    m dv/dt = m g - F_guide (eq. D.1, v positive down), the guide's damping implicit."""
    fp = cfg.guide.lugre_vector(load_kg)
    mass = cfg.guide.slide_mass_kg + load_kg
    z = v = y = 0.0
    for _ in range(round(seconds / h)):
        zf, damping = lugre_split(z, v, fp)
        v = (mass * v + h * (mass * 9.81 - zf)) / (mass + h * damping)
        z = lugre_z_step(z, v, h, fp)
        y += h * v
    return y


@pytest.mark.parametrize("load", [0.0, 0.5, 1.0, 3.0, 6.0])
def test_guide_lets_the_slide_fall_as_in_the_free_fall_experiments(cfg, load):
    """The thesis's free falls (Fig. D.1) did fall, so the guide's breakaway is below the weight;
    once moving the friction is eq. D.4, Fc + sigma_v v. (Table D.1's Fs equals the weight, the
    release artefact of eq. D.2: with it the slide would not have moved.)"""
    mass = 1.35 + load
    k = 9.1 / mass                                   # sigma_v / m, 1/s  (0.0091 N s/mm)
    a0 = 9.81 - 10.9 / mass                          # g - Fc / m at v = 0, m/s^2
    t = 0.2
    expected = a0 / k * (t - (1.0 - math.exp(-k * t)) / k)      # eq. D.4 integrated from rest
    assert _free_fall_drop_m(cfg, load, t) == pytest.approx(expected, rel=0.05)


def _force_controlled_displacement(fp, amplitude_n, seconds=50.0, mass=2.0, h=1e-4):
    """A mass on the LuGre contact under a 0.04 Hz force (chapter 6.4.2's test); peak |x|."""
    z = v = x = 0.0
    peak = 0.0
    for k in range(int(seconds / h)):
        force = amplitude_n * math.sin(2 * math.pi * 0.04 * k * h)
        z_force, damping = lugre_split(z, v, fp)
        v = (mass * v + h * (force - z_force)) / (mass + h * damping)
        x += h * v
        z = lugre_z_step(z, v, h, fp)
        peak = max(peak, abs(x))
    return peak


def test_presliding_stays_below_stiction(cfg):
    """Below the break-away force (20.4 N on the - side) the contact only strains its
    bristles: displacements stay within Fig. 6.6's +/-0.5 mm; above it, it slides."""
    assert _force_controlled_displacement(cfg.friction.vector, 15.0) < 5e-4
    assert _force_controlled_displacement(cfg.friction.vector, 40.0, seconds=15.0) > 5e-3


def test_steady_state_of_lugre_is_its_static_map(cfg):
    for v in (0.002, 0.01, 0.1, -0.005, -0.2):
        z = 0.0
        for _ in range(20000):
            z = lugre_z_step(z, v, 1e-4, cfg.friction.vector)
        z_force, damping = lugre_split(z, v, cfg.friction.vector)
        assert z_force + damping * v == pytest.approx(table_6_1_force(v * 1e3), rel=1e-6)
        assert steady_friction(v, cfg.friction.vector) == pytest.approx(table_6_1_force(v * 1e3), rel=1e-9)


def _sink_velocity_m_s(cfg, load, command, seconds=1.0):
    rig = TestbenchRig(cfg, load, start_mm=150.0)
    rig.command[0] = command
    run(rig, 0.3)
    start = rig.state[0, hy.S_Y]
    run(rig, seconds)
    return (rig.state[0, hy.S_Y] - start) / seconds, rig


def test_centred_spool_holds_the_bare_slide(cfg):
    velocity, rig = _sink_velocity_m_s(cfg, 0.0, 0.0, 2.0)
    # the leaky, underlapped valve lets it creep a little, as a real closed-centre valve at null
    assert abs(velocity) * 2.0 < 4 * cfg.sensors.encoder_resolution_m                 # < 0.5 mm in 2 s
    assert rig.rod_force_n[0] == pytest.approx(1.35 * 9.81, abs=15)


@pytest.mark.parametrize("load", [3.0, 6.0])
def test_a_load_sinks_at_null_and_a_small_spool_offset_holds_it(cfg, load):
    """The underlapped valve's null pressures cannot carry 3-6 kg (measured: 19 and 53 mm/s
    down), so the load sinks at null; the PI's integrator supplies the holding offset, which
    must stay small (measured 2.0 and 3.4 % of full scale) and leave the rod carrying the weight."""
    sink, _ = _sink_velocity_m_s(cfg, load, 0.0)
    assert sink < -0.005                                                       # down, > 5 mm/s
    low, high = 0.0, 0.05
    assert _sink_velocity_m_s(cfg, load, high)[0] > 0                          # 5 % lifts it
    for _ in range(20):                                                        # bisection on the offset
        mid = 0.5 * (low + high)
        if _sink_velocity_m_s(cfg, load, mid, 0.5)[0] > 0:
            high = mid
        else:
            low = mid
    velocity, rig = _sink_velocity_m_s(cfg, load, 0.5 * (low + high), 2.0)
    assert abs(velocity) * 2.0 < 4 * cfg.sensors.encoder_resolution_m                 # held: < 0.5 mm in 2 s
    assert rig.rod_force_n[0] == pytest.approx((1.35 + load) * 9.81, abs=15)


@pytest.mark.parametrize("load", [0.0, 6.0])
def test_an_unbolted_slide_falls_free_when_the_rod_drops_away_and_lands_on_it(cfg, load):
    """Appendix D on the emulated bench: unbolted, the slide rides on the rod while it holds;
    with the rod pulled down it falls as eq. D.4 (the encoder reads the slide), the load cell
    carries nothing, and it can be bolted again only once it rests on the rod."""
    rig = TestbenchRig(cfg, load, start_mm=270.0)
    rig.command[0] = rig.state[0, hy.S_SPOOL]
    rig.unbolt_slide()
    run(rig, 0.1)                                    # holding: it rides on the rod
    assert rig.gap_m == 0.0 and rig.rod_force_n[0] > 0.5 * (1.35 + load) * GRAVITY_M_S2
    start, sinking = float(rig.stroke_m[0]), -float(rig.slide[1])      # the crude hold lets 6 kg sink
    rig.command[0] = -0.6
    run(rig, 0.1)
    assert rig.gap_m > 0.0 and rig.rod_force_n[0] == 0.0 and not rig.bolt_slide()
    mass = 1.35 + load
    k, a0, t = 9.1 / mass, 9.81 - 10.9 / mass, 0.1
    fallen = a0 / k * (t - (1.0 - math.exp(-k * t)) / k) + sinking * (1.0 - math.exp(-k * t)) / k
    assert start - float(rig.stroke_m[0]) == pytest.approx(fallen, abs=1.5e-3)    # the release's few ms
    run(rig, 1.5)
    assert rig.gap_m == 0.0 and rig.stroke_m[0] == 0.0 and rig.bolt_slide() and rig.bolted


def test_end_stop_holds_the_stroke(cfg):
    rig = TestbenchRig(cfg, 0.0, start_mm=280.0)
    rig.command[0] = 1.0
    run(rig, 1.0)
    assert rig.state[0, hy.S_Y] == pytest.approx(cfg.stroke_m)
    assert rig.state[0, hy.S_V] == 0.0


def test_hexapod_holds_at_home_and_closes_its_loops(cfg):
    rig = HexapodRig(cfg)
    run(rig, 0.5)                        # the chambers settle from their start pressures
    start, _ = rig.platform_pose()
    run(rig, 1.0)
    position, _ = rig.platform_pose()
    assert np.linalg.norm(position - start) < 5e-4
    assert rig.closure_error_m() < 1e-5
    assert np.all(np.isfinite(rig.state))
    # every leg carries a share of the platform's weight: small compressive rod forces
    assert np.all(rig.rod_force_n > 0) and rig.rod_force_n.sum() < 3 * 9.81 * 3
    rig.command[:] = 0.05
    run(rig, 0.3)
    moved, _ = rig.platform_pose()
    assert moved[2] - position[2] > 0.005                           # all legs extend: it rises


@pytest.mark.parametrize("supply_bar", [20.0, 40.0])
def test_the_rigs_start_where_their_valves_held_them(supply_bar):
    """Each leg's chambers start at its valve's steady state for the leg's static force
    (`hydraulics.resting_pressures`): with that holding spool commanded, opening the
    load-holding valves moves no leg. (From PA + PB = supply + tank the level fell toward the
    valve's ~1.5 bar after the ports opened and lurched each hexapod leg ~1 mm at 40 bar.)"""
    cfg = load_config(overrides={"actuator": {"supply_pressure_bar": supply_bar}})
    for rig in (HexapodRig(cfg), TestbenchRig(cfg, 6.0)):
        for i in range(rig.n_legs):
            force = hy.piston_force(rig.state[i, hy.S_PA], rig.state[i, hy.S_PB], cfg.hp)
            *_, rig.command[i], ok = hy.steady_state(float(rig.state[i, hy.S_Y]), force,
                                                     cfg.actuator.supply_pressure_pa, cfg.hp)
            assert ok
        rig.ports_open[:] = 1.0
        start = rig.state[:, hy.S_Y].copy()
        run(rig, 0.1)
        assert np.abs(rig.state[:, hy.S_Y] - start).max() < 0.01e-3


def test_a_diverged_plant_is_counted(cfg):
    """A chamber pressure no hydraulics reaches makes MuJoCo reset the mechanism (its
    warning); the rig counts the period and when it first happened, and a healthy rig none."""
    healthy, broken = HexapodRig(cfg), HexapodRig(cfg)
    broken.state[0, hy.S_PA] = 1e12
    run(healthy, 0.01)
    run(broken, 0.01)
    assert healthy.unstable_periods == 0 and healthy.first_unstable_s is None
    assert broken.unstable_periods >= 1 and broken.first_unstable_s is not None
    bench = TestbenchRig(cfg, 0.0)
    bench.state[0, hy.S_PA] = np.nan
    run(bench, 0.004)
    assert bench.unstable_periods == 2


def test_calibration_subset_within_bounds(cfg):
    """Table A.3 at 60 and 240 mm, all three loads, by linearisation: inside the bounds."""
    rows = calibration.table_a3()
    table = calibration.calibration_table(cfg, rows[[2, 8]])
    for entry in table:
        assert entry["converged"]
        assert entry["within_bounds"], entry
        assert entry["pole_in_region"], entry


def test_calibration_table_regression(cfg):
    """The whole table as documented: 29 of 33 points inside the bounds (the misses are b1 at
    10 mm / 0 kg and b0 at 120 and 150 mm / 3 kg and 10 mm / 6 kg, each within a few percent
    of its bound), every pole pair in the region."""
    summary = calibration.summary(calibration.calibration_table(cfg))
    assert summary["poles_in_region"] == 33
    assert summary["within_bounds"] >= 29
    assert summary["max_abs_error_pct"]["b0"] < 22.0
    assert summary["max_abs_error_pct"]["b1"] < 29.0
    assert summary["max_abs_error_pct"]["k01"] < 18.0


def test_linearisation_matches_a_simulated_step(cfg):
    """The linearised model's pole pair is the one the nonlinear rig rings at."""
    point = calibration.linearise(cfg, 150.0, 3.0)
    assert point.b0 > 0 and point.b1 > 0
    wn = math.sqrt(point.b0)
    assert 70 < wn < 130


@pytest.mark.parametrize("position_mm, load_kg", [(150.0, 0.0), (60.0, 6.0)])
def test_the_disturbance_path_is_the_steady_response_and_chapter_4_4_predicts_it(cfg, position_mm, load_kg):
    """Eq. 4.68's Fe path: its steady velocity per newton (-k02 z0) is what the nonlinear
    chambers' steady state gives at a fixed spool (an oracle apart from the linearisation);
    eq. 4.71 and 4.73 on Kx, Kd, Kp predict k01 and k02 (one pressure state against two
    chambers: within 15 %); the signs of eq. 4.76-4.77."""
    point = calibration.linearise(cfg, position_mm, load_kg)
    y, mass = position_mm * 1e-3, calibration.moving_mass_kg(cfg, load_kg)
    force, ps = mass * GRAVITY_M_S2, cfg.actuator.supply_pressure_pa

    def spool(f, v):
        return hy.steady_state(y, f, ps, cfg.hp, v)[2]
    ds_df = (spool(force + 5.0, 0.0) - spool(force - 5.0, 0.0)) / 10.0
    ds_dv = (spool(force, 1e-4) - spool(force, -1e-4)) / 2e-4
    steady = -ds_df / (point.damping_ns_m * ds_df + ds_dv)          # m/s per N at a fixed spool
    assert -point.k02_mm_n * 1e-3 * point.z0 == pytest.approx(steady, rel=0.03)
    predicted = point.chapter_4_4()
    assert predicted["k01_mm_s_v"] == pytest.approx(point.k01, rel=0.15)
    assert predicted["k02_mm_n"] == pytest.approx(point.k02_mm_n, rel=0.15)
    assert point.kp < 0.0 < point.kd and point.z0 > 0.0 and point.kx > 0.0


def test_config_errors_name_the_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[valve]\nspool_time_constant_ms = -1\n")
    with pytest.raises(ConfigError, match=r"\[valve\]\.spool_time_constant_ms = -1 is out of range"):
        load_config(bad)
    bad.write_text("[valve]\nspool_lag = 1\n")
    with pytest.raises(ConfigError, match=r"unknown key \[valve\]\.spool_lag"):
        load_config(bad)
    bad.write_text("[nope]\n")
    with pytest.raises(ConfigError, match=r"unknown section \[nope\]"):
        load_config(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "missing.toml")


# -- CiA 408 valve driver ---------------------------------------------------------------------

def drive(valve, d, h, m, r=False, setpoint=0.0):
    valve.receive(d, h, m, r, setpoint)
    return valve.on_sync()


def test_valve_state_machine_path_and_reset():
    valve = ValveDriver(command_timeout_syncs=3)
    valve.boot()
    assert valve.state is ValveState.DISABLED
    drive(valve, True, True, True, setpoint=0.5)        # ACTIVE only through HOLD
    assert valve.state is ValveState.HOLD and valve.spool_command == 0.0
    drive(valve, True, True, True, setpoint=0.5)
    assert valve.state is ValveState.ACTIVE and valve.spool_command == 0.5
    drive(valve, True, True, False)
    assert valve.state is ValveState.HOLD
    drive(valve, False, False, False)
    assert valve.state is ValveState.DISABLED


@pytest.mark.parametrize("timeout", [1, 3, 7])
def test_valve_timeout_after_exactly_the_configured_syncs(timeout):
    valve = ValveDriver(command_timeout_syncs=timeout)
    valve.boot()
    drive(valve, True, True, True, setpoint=0.3)
    drive(valve, True, True, True, setpoint=0.3)
    assert valve.state is ValveState.ACTIVE
    for k in range(1, timeout):
        assert valve.on_sync() is None and valve.state is ValveState.ACTIVE, k
    emergency = valve.on_sync()
    assert valve.state is ValveState.FAULT_HOLD and valve.spool_command == 0.0
    assert emergency.reason is FaultReason.COMMAND_TIMEOUT and emergency.error_code == 0x8250
    # commands alone do not leave the fault; a rising edge of R does
    drive(valve, True, True, True, setpoint=0.3)
    assert valve.state is ValveState.FAULT_HOLD
    drive(valve, False, True, True)
    assert valve.state is ValveState.FAULT_DISABLED
    reset = drive(valve, True, True, False, r=True)
    assert valve.state is ValveState.HOLD and reset.error_code == 0


def test_invalid_frames_do_not_refresh_the_timeout():
    valve = ValveDriver(command_timeout_syncs=2)
    valve.boot()
    drive(valve, True, True, False)
    valve.receive_invalid()
    valve.on_sync()
    valve.receive_invalid()
    emergency = valve.on_sync()
    assert emergency.reason is FaultReason.E2E_ERROR


def test_spool_jam_detected():
    valve = ValveDriver(jam_threshold=0.1, jam_syncs=4)
    valve.boot()
    drive(valve, True, True, True, setpoint=0.5)
    drive(valve, True, True, True, setpoint=0.5)
    results = [valve.check_spool(0.0, 0.5) for _ in range(4)]
    assert results[:3] == [None] * 3 and results[3].reason is FaultReason.SPOOL_JAM


def test_a_fast_ramp_the_spool_follows_is_not_a_jam():
    """The monitor compares the spool with the demand it followed over the last period: a
    ramp of 15 % per SYNC (each new setpoint 15 % from the spool) is followed, not jammed."""
    valve = ValveDriver(jam_threshold=0.1, jam_syncs=4)
    valve.boot()
    drive(valve, True, True, True, setpoint=0.0)
    demand = 0.0
    for k in range(1, 12):
        drive(valve, True, True, True, setpoint=0.15 * k)
        actual = demand - 0.02                               # lagging its demand a little
        assert valve.check_spool(actual, demand) is None
        demand = valve.spool_command


@given(roll=st.floats(-3.1, 3.1), pitch=st.floats(-1.5, 1.5), yaw=st.floats(-3.1, 3.1))
@settings(max_examples=200, deadline=None)
def test_the_imu_reports_the_bus_convention_as_scipy_does(roll, pitch, yaw):
    """IMU_ATTITUDE's roll, pitch, yaw of R = Rz(yaw) Ry(pitch) Rx(roll), from the body's
    quaternion through MuJoCo, against SciPy's Euler angles."""
    from scipy.spatial.transform import Rotation

    from plant_emulator.sensors import attitude_rpy
    quat = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat(scalar_first=True)
    np.testing.assert_allclose(attitude_rpy(quat), [roll, pitch, yaw], atol=1e-9)
    np.testing.assert_allclose(attitude_rpy(-quat), [roll, pitch, yaw], atol=1e-9)
