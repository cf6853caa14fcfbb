"""Buses the tests open: a fresh on-host multicast port per test, several buses closed however
a test ends, and a scripted bus on a fake clock for the emulator's process loop."""

from __future__ import annotations

import copy
import socket
from contextlib import ExitStack, contextmanager

import can

from protocol.bus import open_bus
from protocol.outbox import Outbox

GROUP = "239.255.72.80"


def free_port() -> int:
    """A UDP port unique to this test run (the kernel picks it), so parallel runs never mix."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        return s.getsockname()[1]


@contextmanager
def opened(*specs: str):
    """Open several buses; shut all of them down however the test ends."""
    with ExitStack() as stack:
        buses = []
        for spec in specs:
            bus = open_bus(spec)
            stack.callback(bus.shutdown)
            buses.append(bus)
        yield buses


class ScriptedBus:
    """recv() plays a script on a fake clock: ("frame", msg) arrives at once; ("quiet",) lets
    the timeout pass; ("stall", s) wakes s seconds after the timeout (the process was not
    scheduled), with nothing received."""

    def __init__(self, script):
        self.script = list(script)
        self.now = 0.0

    def clock(self) -> float:
        return self.now

    def recv(self, timeout):
        step = self.script.pop(0)
        if step[0] == "frame":
            return step[1]
        self.now += timeout + (step[1] if step[0] == "stall" else 0.0)
        return None

    def send(self, msg):
        pass


def sync_frame(counter: int) -> can.Message:
    box = Outbox("SYNC")
    box.values[0] = counter
    assert box.encode()
    return copy.deepcopy(box.message)
