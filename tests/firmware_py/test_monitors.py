"""What the loop and the supervision's monitors see on the bus (monitors.py, through the real
loop on the emulated rig): missing and E2E-bad sensor frames, a valve's fault, EMCYs (the
nodes' and the controller's own), lost heartbeats, a stalled realtime loop, nodes that
reboot; and how each recovers with RESET."""

import math

import can
import pytest

from physics.hydraulics import S_Y
from protocol.dbc import load_database
from protocol.enums import Ack, Command, EmcyCode, EmuFault, Fault, NmtCommand, NmtState, State, ValveState
from protocol.nodes import CONTROLLER_NODE, IMU_NODE
from tests.support.loops import (
    bus_loop,
    clear,
    command,
    cycles,
    cycles_until_fault,
    cycles_while_starting,
    frames_sent,
    inject,
    nmt,
    valve_states,
    valve_words,
)


def test_missing_sensor_frames_fault_after_the_configured_count_then_reset():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    inject(bus, 1, EmuFault.DROP)                            # the leg node's frames are lost
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault - 1)
    assert ctl.status.state is State.READY                   # transient: still running
    loop.cycle()
    assert ctl.status.state is State.FAULT and ctl.status.fault is Fault.SENSOR_TIMEOUT
    d, h, m, _ = valve_words(loop)
    assert (d, h, m) == (1, 1, 0)                             # FAULT holds the valves
    assert all(math.isfinite(v) for v in ctl.status.position_m)
    clear(bus, 1, EmuFault.DROP)
    cycles(loop, 5)
    assert ctl.status.state is State.FAULT                   # needs an explicit reset
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    cycles(loop, 1)                                           # every sensor reported: estimators restart
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.status.state is State.READY


def test_e2e_corrupted_frames_are_counted_and_fault():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    inject(bus, 1, EmuFault.CORRUPT)
    cycles(loop, ctl.cfg.supervisor.e2e_errors_fault)
    assert loop.stats.e2e_errors >= ctl.cfg.supervisor.e2e_errors_fault
    assert ctl.status.state is State.FAULT and ctl.status.fault is Fault.E2E_ERROR


def test_a_valve_in_fault_faults_the_controller():
    """The controller's commands stop reaching the valve: it times out (CiA 408 FAULT_HOLD,
    EMCY RPDO timeout) and the controller faults on it."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 10)
    inject(bus, CONTROLLER_NODE, EmuFault.DROP)              # the valves ignore VALVE_CMD
    cycles(loop, ctl.cfg.timing.hold_cycles + 5)
    assert valve_states(bus) == [ValveState.FAULT_HOLD]
    assert ctl.status.state is State.FAULT and ctl.status.fault is Fault.VALVE_FAULT


def controller_emcy(bus) -> tuple[int, dict]:
    """How many EMCY_16 the controller sent, and the last one decoded (stock cantools)."""
    message = load_database().get_message_by_name(f"EMCY_{CONTROLLER_NODE}")
    data = bus.last_sent.get(message.frame_id)
    return frames_sent(bus, f"EMCY_{CONTROLLER_NODE}"), (message.decode(data, decode_choices=False)
                                                         if data is not None else {})


def test_the_controller_sends_its_emcy_when_it_latches_and_when_a_reset_clears():
    """A CANopen watcher learns of a controller fault: EMCY_16 with the CiA 301 class
    (SENSOR_TIMEOUT: RPDO timeout) and the fault code in DETAIL; ERROR_CODE 0 after RESET."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    assert controller_emcy(bus)[0] == 0
    inject(bus, 1, EmuFault.DROP)
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault + 5)
    count, emcy = controller_emcy(bus)
    assert ctl.status.state is State.FAULT and count == 1     # once per latch, not per cycle
    assert emcy["ERROR_CODE"] == EmcyCode.RPDO_TIMEOUT and emcy["DETAIL"] == Fault.SENSOR_TIMEOUT
    assert emcy["STATE"] == State.FAULT and emcy["ERROR_REGISTER"] == 1 and emcy["INFO"] == 1     # leg 1
    clear(bus, 1, EmuFault.DROP)
    cycles(loop, 2)
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    cycles(loop, 2)
    count, emcy = controller_emcy(bus)
    assert count == 2 and emcy["ERROR_CODE"] == 0 and emcy["DETAIL"] == 0 and emcy["STATE"] == State.IDLE


@pytest.mark.parametrize("node, fault", [(1, Fault.VALVE_FAULT), (IMU_NODE, Fault.SENSOR_FAULT)])
def test_an_emcy_faults_the_controller_named_by_its_source(node, fault):
    loop, ctl, bus = bus_loop("hexapod", "pi")
    cycles(loop, 20)
    message = load_database().get_message_by_name(f"EMCY_{node}")
    data = message.encode({"ERROR_CODE": 0x6000, "ERROR_REGISTER": 1, "STATE": 0, "DETAIL": 1, "SYNC_COUNTER": 0,
                           "INFO": 0})
    bus.deliver(can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False))
    cycles(loop, 2)
    assert ctl.status.state is State.FAULT and ctl.status.fault is fault
    assert loop.stats.faults == 1                              # the daemon's summary counts it


def test_a_lost_heartbeat_faults_in_the_cycle_that_reads_it():
    """The IMU node falls silent (its heartbeat too; the legs go on): the first cycle that
    reads its heartbeat overdue faults HEARTBEAT_LOST, and that cycle's VALVE_CMD already
    holds the valves."""
    timeout_s = 0.150
    loop, ctl, bus = bus_loop("hexapod", "pi", {"timing": {"heartbeat_timeout_ms": timeout_s * 1e3}})
    cycles(loop, 5)
    inject(bus, IMU_NODE, EmuFault.SILENT)
    k = cycles_until_fault(loop, 200)
    assert ctl.status.fault is Fault.HEARTBEAT_LOST
    assert k <= (timeout_s + ctl.cfg.timing.heartbeat_s) / 0.002 + 1       # within the timeout of its last beat
    assert valve_words(loop)[2] == 0                           # M = 0 in the very cycle


def test_a_stalled_realtime_loop_faults_overrun_and_stays_held_until_reset():
    loop, ctl, bus = bus_loop("testbench", "pi", pacing="realtime")
    cycles(loop, 20)
    assert ctl.status.state is State.READY
    bus.clock.advance(0.050)                                  # SIGSTOP for 50 ms
    loop.cycle()
    assert ctl.status.state is State.FAULT and ctl.status.fault is Fault.OVERRUN
    assert loop.stats.faults == 1                             # the stall's fault is counted too
    for _ in range(100):
        loop.cycle()
        assert valve_words(loop)[2] == 0                      # M = 0: held, no motion
    assert ctl.status.state is State.FAULT
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    loop.cycle()                                              # every sensor reported: estimators restart
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.status.state is State.READY


def test_lockstep_cycles_close_at_the_emulators_last_frame_not_at_the_timeout():
    """Lockstep: a lost LEG_STATE costs no wait (EMU_TRUTH of the same SYNC closes the window)
    and is still counted missing; an EMU_TRUTH of an earlier SYNC closes nothing."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 5)
    inject(bus, 1, EmuFault.DROP)
    t0, missing = bus.clock(), loop.stats.missing_frames
    cycles(loop, 3)
    assert bus.clock() - t0 == pytest.approx(3 * bus.period_s)          # no timeout waited out
    assert loop.stats.missing_frames - missing == 3
    clear(bus, 1, EmuFault.DROP)
    cycles(loop, 2)                                           # its first frame back fails E2E (counter jump)
    # each cycle's window closes at its LEG_STATE, leaving that SYNC's EMU_TRUTH queued ahead
    # of the next cycle's frames: heard then, it must not close the next window
    missing = loop.stats.missing_frames
    cycles(loop, 50)
    assert loop.stats.missing_frames == missing


def test_nodes_that_reboot_are_started_again_on_reset():
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    nmt(bus, NmtCommand.RESET_NODE, 1)                        # the node reboots: PRE-OPERATIONAL, silent
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault + 2)
    assert ctl.status.fault in (Fault.SENSOR_TIMEOUT, Fault.VALVE_FAULT)
    heartbeat_s, period_s = bus.emulator.cfg.nodes.heartbeat_s, bus.period_s
    cycles(loop, math.ceil(heartbeat_s / period_s) + 1)            # its first heartbeat after the boot-up
    assert loop.hardware.nmt_state[1] == NmtState.PRE_OPERATIONAL
    starts = frames_sent(bus, "NMT")
    ctl.host.command(int(Command.RESET), 0, 1)
    assert cycles_while_starting(loop)                        # identified again beside the cycle ...
    assert frames_sent(bus, "NMT") == starts + 1             # ... then started
    # the cycles went on meanwhile, the silent node no timeout while it was being identified
    assert ctl.status.state is State.IDLE and bus.emulator.nmt[1] == NmtState.OPERATIONAL
    cycles(loop, 10)
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.status.state is State.READY and valve_states(bus) == [ValveState.ACTIVE]


def test_after_reset_enable_waits_for_every_sensor_and_holds_where_it_reads():
    """A sensor node silent, RESET, the node back reading 30 mm elsewhere (the rod moved while
    unseen): ENABLE is refused until it has reported, then the estimators start there and
    the leg is held where it is, not driven to where it was last seen."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    cycles(loop, 20)
    inject(bus, 1, EmuFault.DROP)
    cycles(loop, 10)
    assert ctl.status.state is State.FAULT and ctl.status.fault is Fault.SENSOR_TIMEOUT
    bus.sim.rig.state[0, S_Y] += 0.030                         # the rod moved 30 mm while unseen
    assert command(ctl, Command.RESET) is Ack.ACCEPTED and ctl.status.state is State.IDLE
    cycles(loop, 2)
    assert command(ctl, Command.ENABLE) is Ack.BAD_STATE      # still silent
    clear(bus, 1, EmuFault.DROP)
    cycles(loop, 2)               # its first frame's alive counter jumped the silence: E2E rejects it
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 100)
    assert ctl.status.state is State.READY, ctl.status.fault.name
    stroke = float(bus.sim.rig.stroke_m[0])
    assert abs(ctl.status.reference_m[0] - stroke) < 1e-3 and abs(loop.meas.position_m[0] - stroke) < 1e-3
