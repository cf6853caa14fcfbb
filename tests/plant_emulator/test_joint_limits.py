"""The emulated mechanism's joints stop where the rig's do (plant_emulator/mechanism.py,
`joint_limits`): a platform shoved sideways with its legs free lies down on its universal
joints' cones (Table 8.1: +/-90 deg) instead of folding through its base, and the rig
reports the stop."""

import mujoco
import numpy as np
import pytest

from plant_emulator.mechanism import Mechanism
from plant_emulator.params import load_config
from plant_emulator.rig_geometry import read_rig_geometry
from plant_emulator.rigs import make_rig

SHOVE_N, SHOVE_S, RUN_S = 150.0, 1.0, 3.0


def _shoved(limits: bool) -> tuple[float, float, bool]:
    """(lowest platform height m, largest tilt deg, a joint on its stop) over the run."""
    mech = Mechanism(read_rig_geometry(), joint_limits=limits)
    model, data = mech.model, mech.data
    rot = np.empty(9)
    lowest, tilt, stopped = np.inf, 0.0, False
    for k in range(int(RUN_S / model.opt.timestep)):
        data.xfrc_applied[mech.platform_body] = (SHOVE_N, 0, 0, 0, 0, 0) if k * model.opt.timestep < SHOVE_S else 0
        mujoco.mj_step(model, data)
        mujoco.mju_quat2Mat(rot, data.qpos[mech.free_qpos + 3:mech.free_qpos + 7])
        lowest = min(lowest, data.qpos[mech.free_qpos + 2])
        tilt = max(tilt, float(np.degrees(np.arccos(np.clip(rot[8], -1.0, 1.0)))))
        stopped |= mech.at_joint_limit()
    return lowest, tilt, stopped


def test_a_lost_platform_lies_on_its_joints_instead_of_folding_through_its_base():
    lowest, tilt, stopped = _shoved(True)
    assert lowest > -0.03 and tilt < 90.0 and stopped
    free_lowest, free_tilt, _ = _shoved(False)
    assert free_lowest < -0.5 and free_tilt > 170.0            # without the joints' stops: folded over


def test_the_hinges_cone_is_centred_on_the_vertical_leg():
    mech = Mechanism(read_rig_geometry(), joint_limits=True)
    centre = mech.hinge_range.mean(axis=1)
    assert np.allclose(mech.hinge_range[:, 1] - mech.hinge_range[:, 0], np.pi)    # +/-90 deg
    assert np.all(np.abs(centre) < np.radians(6.0))            # the legs stand within 5 deg of vertical
    assert not mech.at_joint_limit()                           # home is far inside


@pytest.mark.parametrize("pose_mm", [(0.0, 0.0, 583.5), (200.0, 0.0, 631.0), (-100.0, 100.0, 760.0)])
def test_the_hexapods_rig_reports_no_stop_inside_the_workspace(pose_mm):
    rig = make_rig("hexapod", load_config(), 0.0)
    rig.mechanism.set_pose(np.array(pose_mm) * 1e-3, np.array([1.0, 0.0, 0.0, 0.0]))
    assert not rig.mechanism.at_joint_limit() and rig.joint_limit_periods == 0
