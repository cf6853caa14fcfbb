"""The emulator's nodes and a controller's loop in one process, on a bus between them
(python-can's `send`/`recv` surface): what the controller sends, the emulator handles at
once; what the emulator sends waits in the controller's receive queue. The real loop, codecs,
E2E, nodes and physics, with no sockets and no scheduler: for tests and benchmarks.

Time is a clock of its own that both sides read: each SYNC advances it one period, and a
`recv` that finds nothing waits out its timeout on it. Runs repeat exactly (lockstep).
`outside` (a pair of callables) is called as the emulator's work begins and ends: what an
allocation probe of the controller's cycle uses to leave the plant out.
"""

from __future__ import annotations

from collections import Counter, deque

import can

from plant_emulator.emulator import Emulator
from plant_emulator.params import EmulatorConfig
from protocol.canopen_layout import LAYOUT_FILE
from protocol.codec import CODECS


def _nothing() -> None:
    pass


class SimulatedClock:
    def __init__(self):
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        self.now_s += max(seconds, 0.0)


class _EmulatorSide:
    """The emulator's end: its frames go to the controller's queue."""

    def __init__(self, bus: LoopbackBus):
        self.bus = bus

    def send(self, msg, timeout=None) -> None:
        self.bus.deliver(msg)


class LoopbackBus:
    """The controller's end of a bus with `rig` (configured by `cfg`) emulated behind it, as
    `devices` (the project's own nodes, or stock CANopen devices as `layout` places them)."""

    def __init__(self, rig, cfg: EmulatorConfig, outside=None, devices: str = "hydrapod", layout=LAYOUT_FILE):
        self.enter, self.leave = outside or (_nothing, _nothing)
        self.clock = SimulatedClock()
        self.period_s = cfg.nodes.sync_period_s
        self.queue: deque[can.Message] = deque()
        self.sent: Counter = Counter()                 # frames the controller sent, by id
        self.last_sent: dict[int, bytes] = {}          # ... and the data of each id's last one
        self.emulator = Emulator(_EmulatorSide(self), rig, cfg, clock=self.clock, devices=devices, layout=layout)
        self.emulator.boot()
        self._sync_id = CODECS["SYNC"].frame_id

    @property
    def sim(self):
        """The simulated rig behind the nodes (its valves, sensors, physics and faults)."""
        return self.emulator.sim

    def deliver(self, msg) -> None:
        """A frame for the controller (the emulator's, or a third node's a test puts on the bus)."""
        self.queue.append(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data),
                                      is_extended_id=msg.is_extended_id, timestamp=0.0))

    # python-can's bus surface, as the controller's loop uses it --------------------------------
    def send(self, msg, timeout=None) -> None:
        self.enter()
        frame_id = msg.arbitration_id
        self.sent[frame_id] += 1
        self.last_sent[frame_id] = bytes(msg.data)
        if frame_id == self._sync_id:
            self.clock.advance(self.period_s)
        self.emulator.handle(can.Message(arbitration_id=frame_id, data=bytes(msg.data),
                                         is_extended_id=msg.is_extended_id, timestamp=0.0))
        self.leave()

    def recv(self, timeout=None):
        self.enter()
        self.emulator.poll()
        if not self.queue and timeout:
            self.clock.advance(timeout)
            self.emulator.poll()
        self.leave()
        return self.queue.popleft() if self.queue else None

    def set_filters(self, filters=None) -> None:
        """Every frame reaches the loop, which counts what it does not know."""

    def shutdown(self) -> None:
        """Nothing to close."""
