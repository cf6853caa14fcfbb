"""Issue 8, item 1: the controller's identification tests (HOST_TEST, chapter 6.4) on the test
bench: the valve input of an open-loop step and of a force-controlled sine, when they are
accepted, how they end, and that a cycle with a test running allocates nothing."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.excitation import IdentificationSignal
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from physics.actuator import piston_force
from protocol.enums import Ack, Command, Fault, State, TestMode
from tests.alloc_probe import allocations
from tests.rig_loop import make_loop

PERIOD = 0.002


class Driven:
    """A controller updated by hand with set measurements (no bus)."""

    def __init__(self, rig: str = "testbench", y_m: float = 0.150):
        # set measurements, no plant behind them: neither the actuators' model nor a load cell's noise
        cfg = load_config(overrides={"residuals": {"enabled": False, "load_cell_noise_n": 0.0}})
        self.ctl = Controller(cfg, rig, PERIOD, CONTROLLER_NAMES["pi"])
        self.meas, self.cmd = self.ctl.new_interfaces()
        self.meas.position_m[:] = y_m
        self.meas.fresh[:] = True
        self.meas.valve_state[:] = 3
        self.ctl.activated(auto_enable=True)
        self.update()
        assert self.ctl.state is State.READY

    def update(self) -> None:
        self.ctl.update(self.meas, self.cmd)

    def with_pressures(self, pa_pa: float = 12e5, pb_pa: float = 10e5) -> "Driven":
        self.meas.pa_pa[:] = pa_pa
        self.meas.pb_pa[:] = pb_pa
        self.meas.pressure_valid[:] = True
        return self


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
    assert Driven().ctl.test_command(TestMode.VALVE_STEP, 0.3, 0.0, 1.2) is Ack.BAD_STATE         # no pressure yet
    ctl = Driven().with_pressures().ctl
    assert ctl.test_command(7, 0.3, 0.0, 1.2) is Ack.BAD_ARGUMENT                            # unknown mode
    assert ctl.test_command(TestMode.VALVE_STEP, 0.3, 0.0, 0.0) is Ack.BAD_ARGUMENT               # no duration
    assert ctl.test_command(TestMode.VALVE_STEP, 30.0, 0.0, 1.0) is Ack.BAD_ARGUMENT              # beyond saturation
    assert ctl.test_command(TestMode.VALVE_STEP, math.nan, 0.0, 1.0) is Ack.BAD_ARGUMENT
    assert ctl.test_command(TestMode.ABORT, 0.0, 0.0, 0.0) is Ack.BAD_STATE                       # nothing to abort
    ctl.sup.command(Command.DISABLE, 0)                                                       # IDLE
    assert ctl.test_command(TestMode.VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_STATE
    hexapod = Controller(load_config(), "hexapod", PERIOD, CONTROLLER_NAMES["pi"])
    assert hexapod.test_command(TestMode.VALVE_STEP, 0.3, 0.0, 1.0) is Ack.BAD_ARGUMENT


def test_a_valve_step_drives_the_valve_then_the_leg_holds_where_it_stopped():
    rig = Driven().with_pressures()
    ctl = rig.ctl
    assert ctl.test_command(TestMode.VALVE_STEP, 0.25, 0.0, 0.4) is Ack.ACCEPTED
    assert ctl.state is State.RUNNING
    for k in range(200):
        rig.meas.position_m[:] = 0.150 + 0.00005 * k            # the leg moving up
        rig.update()
        if k < 199:
            assert ctl.joint.u_v[0] == 0.25 and rig.cmd.spool[0] == pytest.approx(0.025)
    assert ctl.state is State.READY and not ctl.test.running
    rig.update()
    assert ctl.reference.yr[0] == pytest.approx(ctl.joint.kalman_x[0, 0], abs=1e-3)   # held near where it ended
    assert ctl.sup.fault_code is Fault.NONE


def test_abort_stop_and_a_fault_each_end_a_test():
    rig = Driven().with_pressures()
    ctl = rig.ctl
    ctl.test_command(TestMode.FORCE_SINE, 0.0, 10.0, 5.0)
    rig.update()
    assert ctl.test_command(TestMode.ABORT, 0.0, 0.0, 0.0) is Ack.ACCEPTED
    assert ctl.state is State.READY and not ctl.test.running
    ctl.test_command(TestMode.FORCE_SINE, 0.0, 10.0, 5.0)
    assert ctl.host_command(Command.STOP, 0) is Ack.ACCEPTED
    assert not ctl.test.running and ctl.state is State.STOPPING
    rig = Driven().with_pressures()
    rig.ctl.test_command(TestMode.VALVE_STEP, 0.25, 0.0, 1.0)
    rig.ctl.sup.fault(Fault.SENSOR_TIMEOUT)
    rig.update()
    assert not rig.ctl.test.running and rig.cmd.active[0] == 0.0         # valves hold


def test_a_cycle_with_a_test_running_allocates_no_numpy_memory():
    loop, ctl, bus = make_loop("testbench", "pi", {"timing": {"heartbeat_timeout_ms": 60000.0}})
    loop.meas.pa_pa[:], loop.meas.pb_pa[:] = 15e5, 12e5    # the fake bus sends no LEG_PRESSURE: they stay
    loop.meas.pressure_valid[:] = True

    def run(n):
        for _ in range(n):
            if not ctl.test.running:                # an event between cycles, as HOST_TEST is
                assert ctl.test_command(TestMode.FORCE_SINE, 0.0, 5.0, 1.0) is Ack.ACCEPTED
            loop.cycle()

    run(600)
    grown, gained = allocations(lambda: run(5000))
    assert grown == []
    assert gained < 8192, f"traced memory grew by {gained} bytes"
    assert ctl.sup.fault_code is Fault.NONE and ctl.test.running
