"""A controller against the emulated rig in one process.

`InProcessLoop`, without a bus: each cycle the
simulated rig's SYNC (its valves apply the last commands, its sensors sample through the
wire's codecs into the Measurements, its physics runs one period), the controller's update,
its valve commands latched for the next SYNC, then its host work. The host's frames go in
through the controller's `HostLink`, as the loop would put them, and their acknowledgements
come back out of it.

How the design tools, the controller bench and the fuzzer run a controller; HIL runs over a
bus are the judge of record (in-process figures land within a few % of them).

`bus_loop`: the controller's real loop (SYNC, collect, read, update, write) on an in-process
bus with the emulator's nodes behind it (`plant_emulator.loopback_bus`): what the tests of the
loop and the allocation report drive.
"""

from __future__ import annotations

import math

import numpy as np

from firmware_py.config import ControllerConfig
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime.loop import ControllerLoop
from plant_emulator.loopback_bus import LoopbackBus
from plant_emulator.params import LOCKSTEP_SYNC_TIMEOUT_PERIODS, EmulatorConfig, build, merge
from plant_emulator.rigs import make_rig
from plant_emulator.simulated_rig import SimulatedRig
from protocol.enums import Ack, AckKind, State, time_scale_from_wire

PERIOD_S = 0.002


class HostRefused(ValueError):
    """The controller did not accept a host frame: its acknowledgement names why."""


class InProcessLoop:
    """A controller (`kind` by name) and the emulator's `rig` ("hexapod": carrying `load_kg`
    on the platform; "testbench": the load on the slide). `seed` makes the sensors' noise
    repeatable; `rig_model` gives another rig (a `LinearRig`) in place of the emulator's."""

    def __init__(self, controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, kind: str,
                 load_kg: float = 0.0, seed: int = 7, rig: str = "hexapod", rig_model=None):
        self.rig = rig_model if rig_model is not None else make_rig(rig, emulator_cfg, load_kg)
        self.sim = SimulatedRig(self.rig, emulator_cfg, rng=np.random.default_rng(seed))
        # the controller at the emulator's SYNC period (PERIOD_S unless its [nodes] say otherwise)
        self.ctl = Controller(controller_cfg, rig, emulator_cfg.nodes.sync_period_s, CONTROLLER_NAMES[kind])
        self.meas, self.cmd = self.ctl.new_interfaces()
        self.acks: dict[tuple[int, int], Ack] = {}     # (AckKind, SEQ) -> result, as they come
        self.time_scale = math.nan                     # the last ack's TIME_SCALE (NaN: none)
        self.seq = 1                                   # HOST_CMD and HOST_TEST
        self.waypoint_seq = 0

    @property
    def status(self):
        return self.ctl.status

    def cycle(self) -> None:
        self.sim.read(self.meas)
        self.ctl.update(self.meas, self.cmd)
        self.sim.write(self.cmd)
        self.ctl.after_write()
        acks = self.ctl.host.acks
        while acks:
            kind, seq, result, wire = acks.popleft()
            self.time_scale = time_scale_from_wire(wire)
            self.acks[(kind, seq % 256)] = Ack(result)

    def cycles(self, count: int) -> None:
        for _ in range(count):
            self.cycle()

    def activate(self, cycles: int = 200, hold_cycles: int = 5) -> None:
        """As the daemon activates: a Reset pulse and `hold_cycles` with the valves holding,
        then READY holding where the rig stands; then `cycles` more."""
        self.ctl.reset_valves()
        self.cycles(hold_cycles)
        self.ctl.activated(True)
        self.cycles(cycles)

    def _answer(self, kind: AckKind, seq: int, limit: int = 100) -> Ack:
        key = (int(kind), seq % 256)
        self.acks.pop(key, None)
        for _ in range(limit):
            self.cycle()
            if key in self.acks:
                return self.acks.pop(key)
        raise TimeoutError(f"no acknowledgement of {kind.name} {seq} in {limit} cycles")

    def command(self, command: int, argument: int = 0) -> Ack:
        """A HOST_CMD, carried out at the next update; its acknowledgement."""
        seq, self.seq = self.seq, (self.seq + 1) % 256
        self.ctl.host.command(int(command), argument, seq)
        return self._answer(AckKind.HOST_CMD, seq)

    def test(self, mode: int, valve_v: float = 0.0, force_n: float = 0.0, duration_s: float = 1.0) -> Ack:
        """A HOST_TEST (an identification test on the test bench); its acknowledgement."""
        seq, self.seq = self.seq, (self.seq + 1) % 256
        self.ctl.host.test(int(mode), seq, valve_v, force_n, duration_s)
        return self._answer(AckKind.TEST, seq)

    def send_waypoint(self, point, segment_s: float, accel_s: float, flags: int, rpy=(0.0, 0.0, 0.0)) -> Ack:
        """A waypoint's three frames (position, orientation, timing); the commit's acknowledgement.
        Waypoints count their own SEQ, and a refused one is sent again with the same (PROTOCOL.md)."""
        seq = self.waypoint_seq
        host = self.ctl.host
        host.waypoint_position(seq & 0x0F, *point)
        host.waypoint_rotation(seq & 0x0F, *rpy)
        host.waypoint_commit(seq & 0x0F, seq, segment_s, accel_s, int(flags))
        ack = self._answer(AckKind.WAYPOINT, seq)
        if ack is Ack.ACCEPTED:
            self.waypoint_seq = (seq + 1) % 256
        return ack

    def waypoint(self, point, segment_s: float, accel_s: float, flags: int, rpy=(0.0, 0.0, 0.0)) -> None:
        """A waypoint that must be accepted (HostRefused otherwise)."""
        ack = self.send_waypoint(point, segment_s, accel_s, flags, rpy)
        if ack is not Ack.ACCEPTED:
            raise HostRefused(f"waypoint {np.round(np.asarray(point) * 1e3, 1)} mm refused: {ack.name}")

    @property
    def faulted(self) -> bool:
        return self.ctl.status.state is State.FAULT


def bus_loop(controller_cfg: ControllerConfig, emulator_cfg: EmulatorConfig, rig: str, kind: str,
             activate: bool = True, pacing: str = "lockstep", outside=None, devices: str = "hydrapod"):
    """(loop, controller, bus): the controller's loop on an in-process bus with the emulator's
    `rig` behind it as `devices` (`outside`: called around the emulator's work); activated by
    default: READY holding where the rig stands."""
    period_s = emulator_cfg.nodes.sync_period_s          # one period for both, as InProcessLoop's
    ctl = Controller(controller_cfg, rig, period_s, CONTROLLER_NAMES[kind])
    if pacing == "lockstep":                 # as `hil run`: the valves' watchdog outlasts the lockstep wait
        emulator_cfg = build(merge(emulator_cfg.raw, {"nodes": {"sync_timeout_periods": LOCKSTEP_SYNC_TIMEOUT_PERIODS}},
                                   "lockstep"))
    bus = LoopbackBus(make_rig(rig, emulator_cfg), emulator_cfg, outside, devices)
    loop = ControllerLoop(bus, ctl, 1.0 / period_s, pacing, clock=bus.clock, log=lambda _: None, devices=devices)
    if activate:
        loop.activate()
    return loop, ctl, bus
