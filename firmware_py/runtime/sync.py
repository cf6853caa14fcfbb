"""Who sends the SYNC. `loop`: the loop itself, when its cycle starts (lockstep, and realtime
on a host bus). `bus`: the bus's own periodic sender, started once with the whole counter
sequence 1..overflow (python-can's `send_periodic` over a message list): on SocketCAN that is
the kernel's broadcast manager, so the SYNC edge on the wire carries no Python jitter, and the
loop starts each cycle when it receives its SYNC. `auto`: `bus` on SocketCAN in realtime
pacing, `loop` otherwise."""

from __future__ import annotations

import can

from program.errors import UserInputError
from protocol.codec import CODECS
from protocol.outbox import Outbox


def check_sync_source(source: str, pacing: str, socketcan: bool) -> None:
    """A source (one of SYNC_SOURCES: the config's check) this pacing and bus can use
    (UserInputError naming the key otherwise). The bus's
    SYNC needs SocketCAN: python-can's other buses send periodic frames from a thread of the
    same bus, which does not receive its own frames, so the loop would never see its SYNC."""
    if source == "bus" and pacing != "realtime":
        raise UserInputError(f"[timing].sync_source = \"bus\" needs --pacing realtime, not {pacing} (lockstep's "
                             "SYNC follows the emulator's frames)")
    if source == "bus" and not socketcan:
        raise UserInputError("[timing].sync_source = \"bus\" needs a SocketCAN bus (the kernel sends the SYNC)")


def bus_sends_sync(source: str, pacing: str, bus) -> bool:
    """Whether the bus's periodic sender makes the SYNC."""
    socketcan = is_socketcan(bus)
    check_sync_source(source, pacing, socketcan)
    return socketcan and pacing == "realtime" if source == "auto" else source == "bus"


def is_socketcan(bus) -> bool:
    try:
        from can.interfaces.socketcan import SocketcanBus
    except ImportError:                                    # not Linux
        return False
    return isinstance(bus, SocketcanBus)


def sync_sequence(overflow: int) -> list[can.Message]:
    """The SYNC frames with counters 1..overflow, the order the periodic sender repeats them."""
    box, frames = Outbox("SYNC"), []
    for counter in range(1, overflow + 1):
        box.values[0] = counter
        box.encode()
        frames.append(can.Message(arbitration_id=box.message.arbitration_id, data=bytes(box.message.data),
                                  is_extended_id=False))
    return frames


class BusSync:
    """The bus's periodic SYNC: started once, stopped at shutdown (python-can's bus shutdown
    stops it too, so a crashed loop never leaves the kernel sending SYNC)."""

    def __init__(self, bus, period_s: float, overflow: int):
        self.bus, self.period_s, self.overflow = bus, period_s, overflow
        self.frame_id = CODECS["SYNC"].frame_id
        self._task = None

    def start(self) -> None:
        if self._task is None:
            self._task = self.bus.send_periodic(sync_sequence(self.overflow), self.period_s)

    def stop(self) -> None:
        if self._task is not None:
            self._task.stop()
            self._task = None
