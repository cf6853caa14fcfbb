"""Inverse dynamics: statics by hand, task-space terms, agreement with the MuJoCo model."""

import copy
import tomllib
from importlib import resources

import numpy as np
import pytest

from firmware_py.mechanics.dynamics import InverseDynamics
from firmware_py.mechanics.geometry import GeometryError, default_geometry, parse_geometry
from firmware_py.mechanics.rotation import rpy_to_quat
from hil.tools.validate_dynamics import forward_run, table_10_2, validate
from plant_emulator.mechanism import Mechanism
from plant_emulator.rig_geometry import read_rig_geometry

GEOMETRY = default_geometry()
RIG = read_rig_geometry()            # the plant's own reading of the same file
RAW = tomllib.loads(resources.files("physics").joinpath("data/geometry.toml").read_text())


def _statics_by_hand(geometry, position, quat):
    """Actuator forces from free-body diagrams (independent of the virtual-work code).

    Leg i (cylinder + rod, A the U centre): the universal joint takes no moment about its
    two axes u1, u2, so the moments about A of the weights and of the platform's force F_i
    at B vanish along u1 and u2. Rod along its axis: tau_i = -(F_i + m_rod g) . u3.
    Platform: sum of -F_i plus its weight is zero, and so are the moments about P.
    """
    from firmware_py.mechanics.rotation import quat_to_matrix
    g = geometry.gravity_m_s2
    rot = quat_to_matrix(quat)
    rows, rhs = [], []
    legs = []
    for i in range(6):
        a = geometry.base_anchor_m[i]
        b_world = rot @ geometry.platform_anchor_m[i]
        leg = position + b_world - a
        u3 = leg / np.linalg.norm(leg)
        u1 = geometry.universal_axis[i]
        u2 = np.cross(u3, u1)
        u2 /= np.linalg.norm(u2)
        u4 = np.cross(u2, u3)
        frame = np.column_stack([u4, u2, u3])
        rho1 = frame @ geometry.cylinder.com_m
        rho2 = leg + frame @ geometry.rod.com_m
        weight_moment = np.cross(rho1, geometry.cylinder.mass_kg * g) + np.cross(rho2, geometry.rod.mass_kg * g)
        for axis in (u1, u2):            # (l x F) . axis = -(weight moment) . axis
            row = np.zeros(18)
            row[3 * i:3 * i + 3] = np.cross(axis, leg)     # (leg x F).axis = F.(axis x leg)
            rows.append(row)
            rhs.append(-weight_moment @ axis)
        legs.append((u3, b_world))
    for k in range(3):                   # platform forces: sum F_i = m_p g
        row = np.zeros(18)
        row[k::3] = 1.0
        rows.append(row)
        rhs.append(geometry.platform.mass_kg * g[k])
    rho_p = rot @ geometry.platform.com_m
    moment = np.cross(rho_p, geometry.platform.mass_kg * g)
    for k in range(3):                   # platform moments about P: sum b_i x F_i = rho_p x m_p g
        row = np.zeros(18)
        for i, (_, b_world) in enumerate(legs):
            e = np.zeros(3)
            e[k] = 1.0
            row[3 * i:3 * i + 3] = np.cross(e, b_world)  # (b x F).e = F.(e x b)
        rows.append(row)
        rhs.append(moment[k])
    forces = np.linalg.solve(np.array(rows), np.array(rhs)).reshape(6, 3)
    return np.array([-(forces[i] + geometry.rod.mass_kg * g) @ legs[i][0] for i in range(6)])


@pytest.mark.parametrize("rpy_deg, offset_mm", [((0, 0, 0), (0, 0, 0)), ((10, -5, 20), (40, -30, 60)),
                                                 ((-20, 15, -40), (-80, 50, 120))])
def test_static_forces_equal_free_body_statics(rpy_deg, offset_mm):
    dyn = InverseDynamics(GEOMETRY)
    position = GEOMETRY.home_position_m + np.array(offset_mm) * 1e-3
    quat = rpy_to_quat(*np.radians(rpy_deg))
    dyn.forces(position, quat, np.zeros(6), np.zeros(6))
    assert np.allclose(dyn.force_n, _statics_by_hand(GEOMETRY, position, quat), rtol=1e-10, atol=1e-10)


def test_wrench_is_mass_matrix_times_acceleration_plus_bias():
    dyn = InverseDynamics(GEOMETRY)
    rng = np.random.default_rng(2)
    for _ in range(20):
        pos = GEOMETRY.home_position_m + rng.uniform(-0.05, 0.05, 3)
        quat = rpy_to_quat(*rng.uniform(-0.3, 0.3, 3))
        twist, accel = rng.normal(size=6), rng.normal(size=6)
        dyn.forces(pos, quat, twist, accel)
        direct = dyn.wrench.copy()
        dyn.task_space_terms(pos, quat, twist)
        assert np.allclose(dyn.mass_matrix @ accel + dyn.bias, direct, atol=1e-12)
        assert np.allclose(dyn.mass_matrix, dyn.mass_matrix.T, atol=1e-12)
        assert np.all(np.linalg.eigvalsh(dyn.mass_matrix) > 0)
        assert np.allclose(dyn.jacobian.T @ dyn.force_n, direct, atol=1e-9)


@pytest.mark.parametrize("name", ["Tx", "Ty", "Tz", "Ry"])
def test_forces_match_mujoco_on_table_10_2(name):
    traj = next(t for t in table_10_2() if t.name == name)
    result = validate(GEOMETRY, RIG, traj, sample_dt_s=0.05)
    assert result.max_abs_error_n < 1e-6, result
    assert result.forward_max_closure_um <= 10.0, result
    assert result.forward_max_leg_error_mm < 0.01, result


def test_mujoco_closure_error_stays_below_10_um_under_load():
    """Forward simulation with the model's forces and a PD loop: the loop closure holds."""
    mech = Mechanism(RIG)
    traj = next(t for t in table_10_2() if t.name == "Tx")
    leg_error, closure = forward_run(GEOMETRY, traj, mech, InverseDynamics(GEOMETRY))
    assert closure <= 10e-6
    assert leg_error < 1e-5


def test_bad_geometry_values_are_one_line_errors():
    raw = copy.deepcopy(RAW)
    raw["legs"]["min_length_mm"] = 700.0
    with pytest.raises(GeometryError, match="home pose"):
        parse_geometry(raw)
    raw = copy.deepcopy(RAW)
    del raw["inertia"]["rod"]["mass_kg"]
    with pytest.raises(GeometryError, match="inertia.rod.mass_kg"):
        parse_geometry(raw)
    raw = copy.deepcopy(RAW)
    raw["inertia"]["platform"]["inertia_kg_mm2"] = [[1, 0, 0], [0, -1, 0], [0, 0, 1]]
    with pytest.raises(GeometryError, match="positive definite"):
        parse_geometry(raw)


def test_the_plant_reads_the_geometry_file_as_the_controller_does():
    """Two independent readings of one file: every anchor, axis, length and inertia agrees."""
    for name in ("base_anchor_m", "platform_anchor_m", "universal_axis", "home_position_m", "gravity_m_s2"):
        np.testing.assert_allclose(getattr(RIG, name), getattr(GEOMETRY, name), atol=1e-15, err_msg=name)
    for name in ("leg_min_m", "stroke_m", "cylinder_length_m", "cylinder_radius_m", "rod_length_m", "rod_radius_m"):
        assert getattr(RIG, name) == pytest.approx(getattr(GEOMETRY, name), rel=1e-15), name
    for body in ("platform", "cylinder", "rod"):
        mine, theirs = getattr(RIG, body), getattr(GEOMETRY, body)
        assert mine.mass_kg == theirs.mass_kg
        np.testing.assert_allclose(mine.com_m, theirs.com_m, atol=1e-15)
        np.testing.assert_allclose(mine.inertia_kg_m2, theirs.inertia_kg_m2, atol=1e-15)


def test_the_declared_payload_is_in_every_dynamics_model_of_the_controller():
    """[hexapod] payload_kg: a point mass at the platform's centre of mass, in the platform
    model, computed torque and the waypoints' force check alike."""
    from firmware_py.config import load_config
    from firmware_py.rig_model import HexapodModel
    base = default_geometry().platform.mass_kg
    rig = HexapodModel(load_config(overrides={"hexapod": {"payload_kg": 3.0}}), 0.002)
    for dynamics in (rig.platform.dynamics, rig.computed_torque.dynamics, rig.check.loads.dynamics):
        assert dynamics.masses[0] == pytest.approx(base + 3.0)
    assert default_geometry().with_payload(0.0).platform.mass_kg == base
