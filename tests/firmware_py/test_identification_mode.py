"""The controller's identification tests (HOST_TEST, chapter 6.4) on the test bench: the valve
input of an open-loop step and of a force-controlled sine, when they are accepted, how they
end (on the emulated bench, in process), and that a cycle with a test running makes no
NumPy buffer."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.motion_control.excitation import IdentificationSignal
from hil.in_process import InProcessLoop
from hil.tools.alloc_count import counting
from physics.actuator import piston_force
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Ack, Command, EmuFault, Fault, State, TestMode
from tests.support.loops import bus_loop, cycles

PERIOD = 0.002


def bench(**emulator) -> InProcessLoop:
    """The test bench in process, READY holding at home, its chamber pressures sampled."""
    loop = InProcessLoop(load_config(), load_emulator_config(overrides=emulator or None), "pi", rig="testbench")
    loop.activate(100)
    assert loop.status.state is State.READY
    return loop


def test_piston_force_is_eq_6_5():
    area = math.pi * 0.006 ** 2
    assert piston_force(20e5, 10e5, area, 0.75) == pytest.approx(area * (20e5 - 0.75 * 10e5))


def test_a_valve_step_holds_its_input_for_its_duration_then_ends():
    signal = IdentificationSignal(0.004, 1.0, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TestMode.VALVE_STEP, 0.3, 0.0, 1.2, cycle=100, piston_force=50.0, u0_v=0.1)
    outputs = [signal.output(100 + k, 0.150, 50.0) for k in range(600)]
    assert all(u == 0.3 for u, _ in outputs)
    assert [done for _, done in outputs].index(True) == 599          # 1.2 s at 500 Hz: 600 cycles


@pytest.mark.parametrize("u, y_m", [(0.5, 0.285), (-0.5, 0.019)])
def test_a_valve_step_ends_at_the_stroke_guard(u, y_m):
    signal = IdentificationSignal(0.004, 1.0, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TestMode.VALVE_STEP, u, 0.0, 1.2, cycle=0, piston_force=0.0, u0_v=0.0)
    assert signal.output(10, y_m, 0.0) == (0.0, True)
    assert signal.output(10, 0.150, 0.0) == (u, False)             # away from the guard it goes on


def test_a_force_sine_is_bumpless_and_proportional_to_the_force_error():
    signal = IdentificationSignal(0.004, 1.0, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TestMode.FORCE_SINE, 0.0, 10.0, 4.0, cycle=0, piston_force=50.0, u0_v=0.12)
    assert signal.output(0, 0.150, 50.0)[0] == pytest.approx(0.12)            # at its start: the hold's input
    # a quarter period in: the reference is 60 N; at 55 N measured (for 1 s: the 1 Hz low-pass has
    # settled) the valve opens 4 mV/N x 5 N more
    u = [signal.output(k, 0.150, 55.0)[0] for k in range(1, 501)]
    assert u[-1] == pytest.approx(0.12 + 0.004 * 5.0, abs=1e-4)
    first_reference_n = 10.0 * math.sin(2 * math.pi * PERIOD / 4.0)
    assert u[0] == pytest.approx(0.12 + 0.004 * (first_reference_n - 5.0 * signal.filter_gain))
    assert signal.output(1999, 0.150, 50.0)[1] and not signal.output(1998, 0.150, 50.0)[1]


def test_the_force_loop_passes_little_of_the_pressure_noise_to_the_valve():
    """1 N of white noise on F_p at 500 Hz: through the 1 Hz low-pass the valve sees ~8 % of
    what K alone would pass (a raw loop jitters the piston below the sensor's step)."""
    signal = IdentificationSignal(0.004, 1.0, 0.020, 0.304, 10.0, PERIOD)
    signal.start(TestMode.FORCE_SINE, 0.0, 0.0, 20.0, cycle=0, piston_force=50.0, u0_v=0.0)
    noise = np.random.default_rng(3).normal(0.0, 1.0, 5000)
    u = np.array([signal.output(k, 0.150, 50.0 + noise[k])[0] for k in range(5000)])
    assert np.std(u) < 0.15 * 0.004 * 1.0


def test_a_test_is_accepted_only_when_it_can_run():
    fresh = InProcessLoop(load_config(), load_emulator_config(), "pi", rig="testbench")
    fresh.cycle()
    fresh.ctl.activated(True)
    assert fresh.test(TestMode.VALVE_STEP, 0.3, 0.0, 1.2) is Ack.BAD_STATE        # no pressure sample yet
    loop = bench()
    assert loop.test(7, 0.3, 0.0, 1.2) is Ack.BAD_ARGUMENT                            # unknown mode
    assert loop.test(TestMode.VALVE_STEP, 0.3, 0.0, 0.0) is Ack.BAD_ARGUMENT            # no duration
    assert loop.test(TestMode.VALVE_STEP, 30.0, 0.0, 1.0) is Ack.BAD_ARGUMENT           # beyond saturation
    assert loop.test(TestMode.VALVE_STEP, math.nan, 0.0, 1.0) is Ack.BAD_ARGUMENT
    assert loop.test(TestMode.ABORT, 0.0, 0.0, 0.0) is Ack.BAD_STATE                    # nothing to abort
    assert loop.command(Command.DISABLE) is Ack.ACCEPTED                              # IDLE
    assert loop.test(TestMode.VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_STATE
    hexapod = InProcessLoop(load_config(), load_emulator_config(), "pi", rig="hexapod")
    hexapod.activate(20)
    assert hexapod.test(TestMode.VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_ARGUMENT


def test_a_valve_step_drives_the_valve_then_the_leg_holds_where_it_stopped():
    loop = bench()
    status = loop.status
    start = float(loop.rig.stroke_m[0])
    assert loop.test(TestMode.VALVE_STEP, 0.25, 0.0, 0.4) is Ack.ACCEPTED      # 0.25 V: 2.5 % of full input
    assert status.state is State.RUNNING and status.testing
    for _ in range(150):
        loop.cycle()
        assert status.spool[0] == pytest.approx(0.025) and loop.cmd.spool[0] == pytest.approx(0.025)
    loop.cycles(60)
    assert status.state is State.READY and not status.testing
    assert float(loop.rig.stroke_m[0]) > start + 0.005                          # the leg went up
    loop.cycles(100)
    assert status.reference_m[0] == pytest.approx(status.position_m[0], abs=1e-3)   # held near where it ended
    assert abs(float(loop.rig.stroke_m[0]) - status.reference_m[0]) < 1e-3
    assert status.fault is Fault.NONE


def test_abort_stop_and_a_fault_each_end_a_test():
    loop = bench()
    status = loop.status
    assert loop.test(TestMode.FORCE_SINE, 0.0, 10.0, 5.0) is Ack.ACCEPTED
    assert loop.test(TestMode.ABORT, 0.0, 0.0, 0.0) is Ack.ACCEPTED
    assert status.state is State.READY and not status.testing
    assert loop.test(TestMode.FORCE_SINE, 0.0, 10.0, 5.0) is Ack.ACCEPTED
    assert loop.command(Command.STOP) is Ack.ACCEPTED
    assert not status.testing and status.state in (State.STOPPING, State.READY)
    loop = bench()
    status = loop.status
    assert loop.test(TestMode.VALVE_STEP, 0.25, 0.0, 1.0) is Ack.ACCEPTED
    inject = loop.sim.inject
    inject(1, EmuFault.DROP, 0)                          # the leg's frames stop: SENSOR_TIMEOUT
    for _ in range(10):
        loop.cycle()
    assert status.state is State.FAULT and status.fault is Fault.SENSOR_TIMEOUT
    assert not status.testing and loop.cmd.active[0] == 0.0         # valves hold


def test_a_cycle_with_a_test_running_makes_no_numpy_buffer():
    with counting() as counts:
        loop, ctl, bus = bus_loop("testbench", "pi", {"timing": {"heartbeat_timeout_ms": 60000.0}},
                                  outside=(counts.pause, counts.resume))
        cycles(loop, 50)                                 # the chambers' pressures sampled
        ctl.host.test(int(TestMode.FORCE_SINE), 1, 0.0, 5.0, 4.0)
        cycles(loop, 100)
        assert ctl.status.testing
        counts.on()
        cycles(loop, 1500)
        counts.off()
        assert counts.numpy_buffers == 0
    assert ctl.status.fault is Fault.NONE and ctl.status.testing
