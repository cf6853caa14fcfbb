"""The controller's cycle allocates nothing: >= 10,000 steady cycles per controller and rig
through the real loop (SYNC, collect, read, update, write) with the bus replaced by an
in-process fake; zero growth of NumPy-domain traces and of traced memory."""

import numpy as np
import pytest

from firmware_py.control import CONTROLLER_NAMES
from firmware_py.trajectory import through_points
from protocol.enums import State
from tests.alloc_probe import allocations
from tests.rig_loop import make_loop

CYCLES = 10_000


def moving_trajectory(ctl):
    """Back and forth by 5 mm on every leg (closed, so it can be replayed)."""
    start = ctl.reference.hold_position.copy()
    points = np.array([start, start + 0.005, start, start + 0.005, start])
    return through_points(points, 0.1, 0.5)


@pytest.mark.parametrize("rig", ["testbench", "hexapod"])
@pytest.mark.parametrize("controller", list(CONTROLLER_NAMES))
def test_steady_cycles_allocate_no_numpy_memory(rig, controller):
    # tracemalloc slows everything down: a loaded CI machine must not fail this test on a
    # late heartbeat (the heartbeat supervision has its own tests)
    loop, ctl, bus = make_loop(rig, controller, {"timing": {"heartbeat_timeout_ms": 60000.0}})
    assert ctl.state is State.READY
    if ctl.hexapod:
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
    grown, gained = allocations(lambda: run(CYCLES))
    assert grown == []
    assert gained < 8192, f"traced memory grew by {gained} bytes"
    # and the loop really ran: no faults, tracking, E2E clean
    assert ctl.state in (State.RUNNING, State.READY), ctl.sup.fault_code.name
    assert loop.stats.e2e_errors == 0 and loop.stats.missing_frames == 0
    assert not ctl.hexapod or ctl.attitude_check.angle_rad < 2e-3          # IMU frames were compared
    assert np.max(np.abs(ctl.joint.error_m)) < 2e-3             # tracking within 2 mm
