"""The emulator as stock CANopen devices (`Emulator(devices="canopen")`) on a python-can virtual
channel, in a thread of its own; what a master on that channel talks to."""

import threading

import can

from plant_emulator.emulator import Emulator
from plant_emulator.params import load_config
from plant_emulator.process import run
from plant_emulator.rigs import make_rig

# the wall clock between a test's SYNCs is the test's, not 2 ms: the valves' SYNC watchdog at 20 s
SLOW_SYNC = {"nodes": {"sync_timeout_periods": 1e4}}


class CanopenRig:
    def __init__(self, rig: str, channel: str):
        cfg = load_config(overrides=SLOW_SYNC)
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.emulator = Emulator(self.bus, make_rig(rig, cfg), cfg, pacing="lockstep", devices="canopen")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=run, args=(self.emulator, self.bus, self._stop.is_set), daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.bus.shutdown()
