"""The controller's cycle allocates nothing: 2,000 steady cycles per controller and rig
through the real loop (SYNC, collect, read, update, write) with the bus replaced by an
in-process fake; zero growth of NumPy-domain traces and of traced memory."""

import numpy as np
import pytest

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.motion_control.trajectory import through_points
from protocol.enums import State
from tests.alloc_probe import allocations
from tests.rig_loop import make_loop

CYCLES = 2_000                 # a leak of 4 bytes per cycle would reach the 8 kB bound (one
                               # Python object a cycle is 16 bytes or more)


def moving_trajectory(ctl):
    """Back and forth by 5 mm on every leg (closed, so it can be replayed)."""
    start = ctl.reference.hold_position.copy()
    points = np.array([start, start + 0.005, start, start + 0.005, start])
    return through_points(points, 0.1, 0.5)


CASES = [(rig, controller) for rig in ("testbench", "hexapod") for controller in CONTROLLER_NAMES]


@pytest.mark.parametrize("rig,controller", CASES)
def test_steady_cycles_allocate_no_numpy_memory(rig, controller):
    # tracemalloc slows everything down: a loaded CI machine must not fail this test on a
    # late heartbeat (the heartbeat supervision has its own tests)
    # computed torque on the hexapod drives the legs through the platform's dynamics: the
    # emulator's hexapod behind the bus (on independent legs, which the fake's are, its yaw
    # loop has no inertia to act on and goes unstable within ~900 cycles)
    emulated = rig == "hexapod" and controller == "computed-torque"
    loop, ctl, bus = make_loop(rig, controller, {"timing": {"heartbeat_timeout_ms": 60000.0}}, emulated=emulated)
    assert ctl.state is State.READY
    if ctl.hexapod and bus.imu_rpy is None:
        bus.imu_rpy = [0.0, 0.0, 0.0]              # the attitude cross-check runs in the window too
    trajectory = moving_trajectory(ctl)

    def run(n):
        for _ in range(n):
            if not ctl.reference.moving:           # replay: RUNNING again (an event, outside the window)
                ctl.reference.play(trajectory, [1], ctl.cycles)
                ctl.sup.start_running()
            loop.cycle()

    run(500)
    # replays happen at cycle multiples of the trajectory length; the window starts on one
    # with the emulator stepping in this process: the bytes gained by the controller's code
    sources = ("*/firmware_py/*", "*/protocol/*") if emulated else None
    grown, gained = allocations(lambda: run(CYCLES), sources)
    assert grown == []
    assert gained < 8192, f"traced memory grew by {gained} bytes"
    # and the loop really ran: no faults, tracking, E2E clean
    assert ctl.state in (State.RUNNING, State.READY), ctl.sup.fault_code.name
    assert loop.stats.e2e_errors == 0 and loop.stats.missing_frames == 0
    # IMU frames were compared (the emulator's IMU reads the true attitude, the encoders' DK
    # is quantised: a few mrad apart)
    limit = ctl.attitude_check.limit_rad if emulated else 2e-3
    assert not ctl.hexapod or ctl.attitude_check.angle_rad < limit
    assert np.max(np.abs(ctl.joint.error_m)) < 2e-3             # tracking within 2 mm
