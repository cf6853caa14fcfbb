"""The limit monitors (monitors.py) at an end stop: after a POSITION_LIMIT, RESET + ENABLE
holds the leg just inside the guard and brings it back, and a leg that goes further out
instead faults again. Through the real loop on the emulated test bench."""

from physics.hydraulics import S_Y
from protocol.enums import Ack, Command, Fault, State
from tests.support.loops import bus_loop, command, cycles


def at_the_top_stop(gap_m: float):
    """The bench with its piston put `gap_m` from the top end stop while READY: faulted
    POSITION_LIMIT."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    bus.sim.rig.state[0, S_Y] = ctl.rig.stroke_m - gap_m
    cycles(loop, 3)
    assert ctl.status.fault is Fault.POSITION_LIMIT
    return loop, ctl, bus


def test_reset_and_enable_at_the_end_stop_comes_back_inside_the_guard():
    """RESET + ENABLE at the end stop holds just inside the guard and brings the leg back; it
    does not re-fault at once (the only way off the stop)."""
    loop, ctl, bus = at_the_top_stop(0.4e-3)
    guard = ctl.rig.stroke_m - ctl.cfg.limits.stroke_margin_m
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    cycles(loop, 5)
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    assert ctl.status.hold_m[0] < guard
    cycles(loop, 400)
    assert ctl.status.state is State.READY and ctl.status.fault is Fault.NONE
    assert bus.sim.rig.stroke_m[0] < guard


def test_a_recovering_leg_that_goes_further_out_faults():
    loop, ctl, bus = at_the_top_stop(0.6e-3)
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    cycles(loop, 5)
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    bus.sim.rig.state[0, S_Y] = ctl.rig.stroke_m - 0.05e-3       # pushed on, past the slack
    cycles(loop, 2)
    assert ctl.status.fault is Fault.POSITION_LIMIT
