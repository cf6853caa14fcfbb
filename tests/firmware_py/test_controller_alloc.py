"""The controller's cycle allocates nothing: 1,000 steady cycles per controller and rig through
the real loop (SYNC, collect, read, update, write) on the in-process bus, the emulated rig
behind it; not one NumPy buffer is made, transient ones included (a counting hook on NumPy's
memory handler, `hil/tools/alloc_count.py`), and nothing the cycle keeps grows (tracemalloc).
The emulator's own work is left out of the count."""

import numpy as np
import pytest

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from hil.tools.alloc_count import counting
from protocol.enums import Command, State, WaypointFlag
from tests.support.alloc import allocations
from tests.support.loops import bus_loop, cycles, send_waypoint
from tests.support.loops import command as host_command

CYCLES = 1_000                 # moving: 2 s, every periodic frame and check many times over
STATE_CYCLES = 250             # each other steady state
TRACED_CYCLES = 500            # a leak of 16 bytes per cycle (one Python object) reaches the 8 kB bound
SEGMENTS = 18                  # the movement: back and forth by 5 mm, 0.2 s a segment (1,800 cycles:
                               # still moving when the counted and traced windows end)
# the hexapod's cases (six legs of emulated physics a cycle) are `make test`'s; the bench's run in `make check`
CASES = [pytest.param(rig, controller, "hydrapod", marks=[pytest.mark.slow] if rig == "hexapod" else [])
         for rig in ("testbench", "hexapod") for controller in CONTROLLER_NAMES]
CASES.append(pytest.param("hexapod", "model-based", "canopen", marks=pytest.mark.slow))    # stock devices' PDOs
# tracemalloc and the counting hook slow everything: the heartbeat supervision has its own tests
RELAXED = {"timing": {"heartbeat_timeout_ms": 60000.0}}


def moving(loop, ctl) -> None:
    """The movement queued and started (host frames: events, before the window)."""
    status = ctl.status
    x, y, z = (0.0, 0.0, float(status.hold_m[0])) if status.rig == "testbench" else ctl.rig.home_pose
    for k in range(SEGMENTS):
        last = k == SEGMENTS - 1
        flags = int(WaypointFlag.START | WaypointFlag.LAST) if last else 0
        assert send_waypoint(ctl, k, x, y, z + (0.005 if k % 2 == 0 else 0.0), segment=0.2, accel=0.05,
                             flags=flags).name == "ACCEPTED"
        loop.cycle()
    assert ctl.status.state is State.RUNNING


def buffers(loop, counts, n: int) -> int:
    """NumPy buffers made in `n` cycles."""
    before = counts.numpy_buffers
    counts.on()
    cycles(loop, n)
    counts.off()
    return counts.numpy_buffers - before


@pytest.mark.parametrize("rig,controller,devices", CASES)
def test_a_steady_cycle_makes_no_numpy_buffer_and_keeps_nothing(rig, controller, devices):
    with counting() as counts:
        loop, ctl, bus = bus_loop(rig, controller, RELAXED, outside=(counts.pause, counts.resume), devices=devices)
        moving(loop, ctl)
        cycles(loop, 200)
        made = buffers(loop, counts, CYCLES)
        assert made == 0, f"{made} NumPy buffers in {CYCLES} cycles moving"
        grown, gained = allocations(lambda: cycles(loop, TRACED_CYCLES), ("*/firmware_py/*", "*/protocol/*"))
        # the loop really ran: moving, no faults, tracking, E2E clean
        status = ctl.status
        assert status.state is State.RUNNING, status.fault.name
        assert loop.stats.e2e_errors == 0 and loop.stats.missing_frames == 0
        assert np.max(np.abs(status.error_m)) < 5e-3                 # following the movement
        # the other steady states: holding (READY), valves locked (IDLE), e-stopped
        for state, command in ((State.READY, None), (State.IDLE, Command.DISABLE), (State.ESTOP, Command.ESTOP)):
            if command is not None:
                host_command(ctl, command)
            while ctl.status.moving:
                loop.cycle()
            cycles(loop, 10)
            assert ctl.status.state is state, ctl.status.state.name
            made = buffers(loop, counts, STATE_CYCLES)
            assert made == 0, f"{made} NumPy buffers in {STATE_CYCLES} cycles {state.name}"
    assert grown == []
    assert gained < 8192, f"traced memory grew by {gained} bytes"


def test_the_count_sees_a_buffer_made_and_freed_inside_the_cycle():
    """The probe itself: an np.empty(6) planted in the update, freed before the cycle ends,
    is one NumPy buffer a cycle (tracemalloc's before-and-after comparison does not see it)."""
    with counting() as counts:
        loop, ctl, bus = bus_loop("testbench", "pi", RELAXED, outside=(counts.pause, counts.resume))
        update = ctl.update

        def planted(meas, cmd):
            np.empty(6)
            update(meas, cmd)

        ctl.update = planted
        counts.on()
        cycles(loop, 100)
        counts.off()
        assert counts.numpy_buffers == 100
        grown, _ = allocations(lambda: cycles(loop, 100))
    assert grown == []
