"""ENABLE where the legs cannot hold the platform is refused BEYOND_CAPACITY (controller.py
`host_command`, waypoints.py `holds`): the valves stay in HOLD, whose sealed chambers hold
beyond the supply, instead of opening to a supply that lets the platform slide. The pose is
where the thesis's model-based controller, sent the circle with 6 kg at 25 bar at 1.88 x,
left the platform after its TRACKING_ERROR: legs 3 and 6 would need 1.59 x their pull."""

import numpy as np

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import ik_batch
from firmware_py.rig_model import HexapodModel
from hil.design.simulate import point_configs
from hil.in_process import InProcessLoop
from protocol.enums import Ack, Command, State

LOST_AT_M = (0.3695, 0.0, 0.5498)


def _strokes(payload_kg: float, position_m) -> np.ndarray:
    geometry = default_geometry().with_payload(payload_kg)
    lengths, _ = ik_batch(geometry, np.array([position_m]), np.array([[1.0, 0.0, 0.0, 0.0]]))
    return lengths[0] - geometry.leg_min_m


def test_the_check_knows_which_poses_the_legs_hold():
    for payload_kg, position_m, held in ((6.0, LOST_AT_M, False), (0.0, LOST_AT_M, True),
                                         (6.0, (0.2, 0.0, 0.631), True)):
        cfg, _ = point_configs(payload_kg, 25.0)
        rig = HexapodModel(cfg, 0.002)
        assert rig.check.holds(_strokes(payload_kg, position_m), 0.0) is held, (payload_kg, position_m)
        assert rig.check.holds(rig.home_strokes, 0.0)


def test_enable_where_the_legs_cannot_hold_is_refused_and_the_valves_stay_held():
    cfg, emulator = point_configs(6.0, 25.0)
    loop = InProcessLoop(cfg, emulator, "computed-torque", 6.0, 1)
    loop.activate()
    assert loop.command(Command.DISABLE) is Ack.ACCEPTED and loop.status.state is State.IDLE
    ctl = loop.ctl
    at_home = ctl.meas.position_m.copy()
    ctl.meas.position_m[:] = _strokes(6.0, LOST_AT_M)        # as the encoders would read it there
    assert ctl.host_command(int(Command.ENABLE), 0) is Ack.BEYOND_CAPACITY
    assert ctl.sup.state is State.IDLE
    ctl.meas.position_m[:] = at_home
    assert ctl.host_command(int(Command.ENABLE), 0) is Ack.ACCEPTED
    assert ctl.sup.state is State.READY
