"""The controller's real loop against the emulated rig in this process (the emulator's nodes
and physics behind `plant_emulator.loopback_bus.LoopbackBus`): what the supervisor, the
residuals, the allocation and the identification tests drive. Host frames go in through the
controller's HostLink only, as the loop puts them there.
"""

from __future__ import annotations

import time

from firmware_py.config import load_config
from hil import in_process
from plant_emulator.params import load_config as load_emulator_config
from protocol.codec import CODECS
from protocol.enums import Ack, AckKind, EmuFault, State
from protocol.interfaces import VC_D, VC_H, VC_M, VC_SPOOL
from protocol.outbox import Outbox


def bus_loop(rig: str, controller: str, overrides: dict | None = None, emulator: dict | None = None,
             pacing: str = "lockstep", activate: bool = True, outside=None, devices: str = "hydrapod"):
    """(loop, controller, bus): the controller's loop on an in-process bus with the emulator's
    `rig` behind it as `devices` (`overrides`, `emulator`: config sections over the packaged
    ones; `outside`: called around the emulator's work); activated by default: READY holding
    where the rig stands."""
    return in_process.bus_loop(load_config(overrides=overrides), load_emulator_config(overrides=emulator), rig,
                               controller, activate, pacing, outside, devices)


def cycles(loop, n: int) -> None:
    for _ in range(n):
        loop.cycle()


def cycles_while_starting(loop, limit_s: float = 5.0) -> bool:
    """Cycles until the rebooted nodes the loop identifies beside its cycle (a thread) have
    been judged, started or refused (False: no identification began); a pause between cycles
    gives that thread its turn."""
    give_up = time.monotonic() + limit_s
    began = False
    while time.monotonic() < give_up:
        loop.cycle()
        began = began or loop.meas.nodes_starting
        if began and not loop.meas.nodes_starting:
            return True
        time.sleep(0.002)
    return False


def cycles_until_fault(loop, limit: int) -> int:
    """Cycles run until the controller faulted (the last one included), at most `limit`."""
    for k in range(1, limit + 1):
        loop.cycle()
        if loop.controller.status.state is State.FAULT:
            return k
    return limit


def _ack(ctl, kind: AckKind, seq: int) -> Ack:
    for k, s, result, _ in reversed(ctl.host.acks):
        if k == kind and s == seq % 256:
            return Ack(result)
    raise AssertionError(f"no acknowledgement of {kind.name} {seq}")


def command(ctl, command: int, argument: int = 0, seq: int = 0) -> Ack:
    """A HOST_CMD as the loop hands it over, carried out as the next update begins; its ack."""
    ctl.host.command(int(command), argument, seq)
    ctl.host.run_before_update(ctl)
    return _ack(ctl, AckKind.HOST_CMD, seq)


def send_waypoint(ctl, seq: int, x: float, y: float, z: float, rpy=(0.0, 0.0, 0.0), segment: float = 1.0,
                  accel: float = 0.2, flags: int = 0) -> Ack:
    """A waypoint's three frames as the loop hands them over: the halves in the update, the
    commit after the cycle's write. Its ack."""
    host = ctl.host
    host.waypoint_position(seq & 0x0F, x, y, z)
    host.waypoint_rotation(seq & 0x0F, *rpy)
    host.waypoint_commit(seq & 0x0F, seq, segment, accel, flags)
    host.run_before_update(ctl)
    ctl.after_write()
    return _ack(ctl, AckKind.WAYPOINT, seq)


def valve_words(loop, leg: int = 0):
    """What the controller last wrote to a leg: (D, H, M, spool)."""
    v = loop.hardware.out_cmd[leg].values
    return v[VC_D], v[VC_H], v[VC_M], v[VC_SPOOL]


def valve_states(bus) -> list[int]:
    """Each emulated valve's CiA 408 state."""
    return [int(valve.state) for valve in bus.sim.valves]


def inject(bus, node: int, fault: EmuFault, param: int = 0) -> None:
    """An EMU_CTRL fault on a node, as the host injects it."""
    bus.emulator.inject(node, fault, param)


def clear(bus, node: int, fault: EmuFault) -> None:
    bus.emulator.sim.clear(node, fault)


def frames_sent(bus, name: str) -> int:
    """How many frames of DBC message `name` the controller sent."""
    return bus.sent[CODECS[name].frame_id]


def nmt(bus, node_command: int, node: int) -> None:
    """An NMT frame to the nodes from another master (a test's)."""
    box = Outbox("NMT")
    box.values[:] = (int(node_command), node)
    assert box.encode()
    bus.emulator.handle(box.message)
