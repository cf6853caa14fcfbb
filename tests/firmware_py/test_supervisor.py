"""The controller's state machine (supervisor.py) and its transitions through the real loop on
the emulated rig: activation, e-stop in the same cycle and reset, enable while ready, home
and park."""

import numpy as np
import pytest

from firmware_py.supervision.supervisor import Supervisor
from protocol.enums import Ack, Command, Fault, State, ValveState
from tests.support.loops import bus_loop, command, cycles, valve_states, valve_words


def test_state_machine_table():
    s = Supervisor()
    assert s.state is State.BOOT
    s.booted(auto_enable=False)
    assert s.state is State.IDLE
    assert s.command(Command.START, 0) is Ack.BAD_STATE
    assert s.command(Command.ENABLE, 0) is Ack.ACCEPTED and s.state is State.READY
    assert s.command(Command.SELECT_CONTROLLER, 4) is Ack.BAD_ARGUMENT
    assert s.command(Command.SELECT_CONTROLLER, 2) is Ack.ACCEPTED and s.controller == 2
    assert s.command(Command.HOME, 0) is Ack.ACCEPTED and s.state is State.HOMING
    assert s.command(Command.SELECT_CONTROLLER, 0) is Ack.BAD_STATE
    s.motion_done()
    assert s.state is State.READY
    assert s.command(Command.PARK, 0) is Ack.ACCEPTED
    s.motion_done()
    assert s.state is State.IDLE                       # parked: valves hold
    assert s.command(Command.RESET, 0) is Ack.BAD_STATE
    assert s.command(99, 0) is Ack.UNKNOWN_COMMAND
    s.fault(Fault.SENSOR_TIMEOUT)
    s.fault(Fault.E2E_ERROR)                            # the first fault stays latched
    assert s.state is State.FAULT and s.fault_code is Fault.SENSOR_TIMEOUT
    assert s.command(Command.ENABLE, 0) is Ack.BAD_STATE
    assert s.command(Command.RESET, 0) is Ack.ACCEPTED and s.state is State.IDLE
    assert s.fault_code is Fault.NONE
    assert s.command(Command.ESTOP, 0) is Ack.ACCEPTED and s.state is State.ESTOP
    s.fault(Fault.OVERRUN)
    assert s.fault_code is Fault.ESTOP
    assert s.command(Command.RESET, 0) is Ack.ACCEPTED and s.state is State.IDLE


@pytest.mark.parametrize("rig", ["testbench", "hexapod"])
def test_activation_enables_and_holds_position(rig):
    loop, ctl, bus = bus_loop(rig, "pi")
    assert ctl.status.state is State.READY
    start = bus.sim.rig.stroke_m.copy()
    cycles(loop, 500)
    assert valve_states(bus) == [ValveState.ACTIVE] * ctl.status.n_legs
    assert np.max(np.abs(bus.sim.rig.stroke_m - start)) < 0.5e-3
    assert ctl.status.fault is Fault.NONE


def test_estop_disables_valves_in_the_same_cycle_and_reset_recovers():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 50)
    assert command(ctl, Command.ESTOP) is Ack.ACCEPTED
    loop.cycle()
    d, h, m, spool = valve_words(loop)
    assert (d, h, m, spool) == (0, 0, 0, 0)                  # written in the cycle that saw the command
    cycles(loop, 3)
    assert valve_states(bus) == [ValveState.DISABLED]        # DISABLED at the next SYNC
    assert command(ctl, Command.ENABLE) is Ack.BAD_STATE
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    loop.cycle()
    assert loop.hardware.out_cmd[0].values[loop.hardware.out_cmd[0].index["CW_R"]] == 1.0    # the reset pulse
    cycles(loop, 3)
    assert ctl.status.state is State.IDLE and valve_states(bus) == [ValveState.HOLD]
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 5)
    assert ctl.status.state is State.READY and valve_states(bus) == [ValveState.ACTIVE]


def test_enable_while_ready_is_a_harmless_repeat():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 5)
    held = ctl.status.hold_m.copy()
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    assert ctl.status.state is State.READY and np.array_equal(ctl.status.hold_m, held)


def test_home_and_park_move_and_park_ends_idle():
    loop, ctl, bus = bus_loop("testbench", "adaptive")
    cfg = ctl.cfg
    assert command(ctl, Command.PARK) is Ack.ACCEPTED
    cycles(loop, 4000)
    assert ctl.status.state is State.IDLE and abs(bus.sim.rig.stroke_m[0] - cfg.testbench.park_m) < 0.5e-3
    assert command(ctl, Command.HOME) is Ack.ACCEPTED
    cycles(loop, 4000)
    assert ctl.status.state is State.READY and abs(bus.sim.rig.stroke_m[0] - cfg.testbench.home_m) < 0.5e-3
