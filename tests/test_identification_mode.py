"""Issue 8, item 1: the controller's identification tests (HOST_TEST, chapter 6.4) on the test
bench: the valve input of an open-loop step and of a force-controlled sine, when they are
accepted, how they end, and that a cycle with a test running allocates nothing."""

import math

import pytest

from firmware_py.config import load_config
from firmware_py.control import CONTROLLER_NAMES, ST_U
from firmware_py.core import ControllerCore
from firmware_py.identification import IdentificationSignal, piston_force_n
from firmware_py.loop import ControllerLoop
from firmware_py.supervisor import Ack, Fault, State
from protocol.values import TEST_ABORT, TEST_FORCE_SINE, TEST_VALVE_STEP
from tests.alloc_probe import allocations
from tests.fake_bus import FakeBus

PERIOD = 0.002


def ready_core(rig: str = "testbench", y_m: float = 0.150) -> ControllerCore:
    core = ControllerCore(load_config(), rig, PERIOD, CONTROLLER_NAMES["pi"])
    core.meas_y[:] = y_m
    core.meas_fresh[:] = True
    core.valve_state[:] = 3
    core.activated(auto_enable=True)
    core.update()
    assert core.state is State.READY
    return core


def with_pressures(core: ControllerCore, pa_pa: float = 12e5, pb_pa: float = 10e5) -> ControllerCore:
    core.meas_pa[:] = pa_pa
    core.meas_pb[:] = pb_pa
    core.pressure_seen[:] = True
    return core


def test_piston_force_is_eq_6_5():
    area = math.pi * 0.006 ** 2
    assert piston_force_n(20e5, 10e5, area, 0.75) == pytest.approx(area * (20e5 - 0.75 * 10e5))


def test_a_valve_step_holds_its_input_for_its_duration_then_ends():
    signal = IdentificationSignal(0.004, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TEST_VALVE_STEP, 0.3, 0.0, 1.2, cycle=100, piston_force=50.0, u0_v=0.1)
    outputs = [signal.output(100 + k, 0.150, 50.0) for k in range(600)]
    assert all(u == 0.3 for u, _ in outputs)
    assert [done for _, done in outputs].index(True) == 599          # 1.2 s at 500 Hz: 600 cycles


@pytest.mark.parametrize("u, y_m", [(0.5, 0.285), (-0.5, 0.019)])
def test_a_valve_step_ends_at_the_stroke_guard(u, y_m):
    signal = IdentificationSignal(0.004, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TEST_VALVE_STEP, u, 0.0, 1.2, cycle=0, piston_force=0.0, u0_v=0.0)
    assert signal.output(10, y_m, 0.0) == (0.0, True)
    assert signal.output(10, 0.150, 0.0) == (u, False)             # away from the guard it goes on


def test_a_force_sine_is_bumpless_and_proportional_to_the_force_error():
    signal = IdentificationSignal(0.004, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TEST_FORCE_SINE, 0.0, 10.0, 4.0, cycle=0, piston_force=50.0, u0_v=0.12)
    assert signal.output(0, 0.150, 50.0)[0] == pytest.approx(0.12)            # at its start: the hold's input
    # a quarter period in: the reference is 60 N; at 55 N measured the valve opens 4 mV/N x 5 N more
    assert signal.output(500, 0.150, 55.0)[0] == pytest.approx(0.12 + 0.004 * 5.0)
    assert signal.output(1999, 0.150, 50.0)[1] and not signal.output(1998, 0.150, 50.0)[1]


def test_a_test_is_accepted_only_when_it_can_run():
    assert ready_core().test_command(TEST_VALVE_STEP, 0.3, 0.0, 1.2) is Ack.BAD_STATE         # no pressure yet
    core = with_pressures(ready_core())
    assert core.test_command(7, 0.3, 0.0, 1.2) is Ack.BAD_ARGUMENT                            # unknown mode
    assert core.test_command(TEST_VALVE_STEP, 0.3, 0.0, 0.0) is Ack.BAD_ARGUMENT               # no duration
    assert core.test_command(TEST_VALVE_STEP, 30.0, 0.0, 1.0) is Ack.BAD_ARGUMENT              # beyond saturation
    assert core.test_command(TEST_VALVE_STEP, math.nan, 0.0, 1.0) is Ack.BAD_ARGUMENT
    assert core.test_command(TEST_ABORT, 0.0, 0.0, 0.0) is Ack.BAD_STATE                       # nothing to abort
    core.sup.command(2, 0)                                                                     # DISABLE: IDLE
    assert core.test_command(TEST_VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_STATE
    hexapod = ControllerCore(load_config(), "hexapod", PERIOD, CONTROLLER_NAMES["pi"])
    assert hexapod.test_command(TEST_VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_ARGUMENT


def test_a_valve_step_drives_the_valve_then_the_leg_holds_where_it_stopped():
    core = with_pressures(ready_core())
    assert core.test_command(TEST_VALVE_STEP, 0.25, 0.0, 0.4) is Ack.ACCEPTED
    assert core.state is State.RUNNING
    for k in range(200):
        core.meas_y[:] = 0.150 + 0.00005 * k                  # the leg moving up
        core.update()
        if k < 199:
            assert core.joint.st[0, ST_U] == 0.25 and core.spool[0] == pytest.approx(0.025)
    assert core.state is State.READY and not core.test.running
    core.update()
    assert core.yr[0] == pytest.approx(core.joint.kalman_x[0, 0], abs=1e-3)     # held near where it ended
    assert core.sup.fault_code is Fault.NONE


def test_abort_stop_and_a_fault_each_end_a_test():
    core = with_pressures(ready_core())
    core.test_command(TEST_FORCE_SINE, 0.0, 10.0, 5.0)
    core.update()
    assert core.test_command(TEST_ABORT, 0.0, 0.0, 0.0) is Ack.ACCEPTED
    assert core.state is State.READY and not core.test.running
    core.test_command(TEST_FORCE_SINE, 0.0, 10.0, 5.0)
    assert core.host_command(9, 0) is Ack.ACCEPTED                       # STOP
    assert not core.test.running and core.state is State.STOPPING
    core = with_pressures(ready_core())
    core.test_command(TEST_VALVE_STEP, 0.25, 0.0, 1.0)
    core.fault(Fault.SENSOR_TIMEOUT)
    core.update()
    assert not core.test.running and core.cw_m[0] == 0.0                 # valves hold


def test_a_cycle_with_a_test_running_allocates_no_numpy_memory():
    cfg = load_config(overrides={"timing": {"heartbeat_timeout_ms": 60000.0}})
    core = ControllerCore(cfg, "testbench", PERIOD, CONTROLLER_NAMES["pi"])
    bus = FakeBus(1, core.home_strokes.copy(), nodes=[1])
    loop = ControllerLoop(bus, core, 500.0, "lockstep", log=lambda _: None)
    loop.activate()
    with_pressures(core, 15e5, 12e5)            # the fake bus sends no LEG_PRESSURE: they stay

    def run(n):
        for _ in range(n):
            if not core.test.running:                # an event between cycles, as HOST_TEST is
                assert core.test_command(TEST_FORCE_SINE, 0.0, 5.0, 1.0) is Ack.ACCEPTED
            loop.cycle()

    run(600)
    grown, gained = allocations(lambda: run(5000))
    assert grown == []
    assert gained < 8192, f"traced memory grew by {gained} bytes"
    assert core.sup.fault_code is Fault.NONE and core.test.running
