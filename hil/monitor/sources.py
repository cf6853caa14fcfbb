"""Where the monitor's frames come from: a live bus (a reader thread that only receives)
or a recorded log replayed at a speed (0: as fast as it can), and the one thing it may send:
the operator's HOST_CMD with --control."""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from pathlib import Path

import can

from hil.logdata import LOG_SUFFIXES
from hil.monitor.view import BusView
from program.errors import UserInputError
from protocol.codec import CODECS
from protocol.enums import Command
from protocol.outbox import Outbox

PROBE_FRAMES = 20_000              # a log must hold a frame of this DBC among its first this many
_IDS = frozenset(c.frame_id for c in CODECS.values())


class LogError(UserInputError):
    """The log cannot be replayed: missing, unreadable, or not this protocol's."""


def check_log(path: str) -> Path:
    """The log as a Path, or a LogError naming what is wrong with it."""
    p = Path(path)
    if p.suffix.lower() not in LOG_SUFFIXES:
        raise LogError(f"{path}: a log is {' or '.join(LOG_SUFFIXES)}")
    if not p.is_file():
        raise LogError(f"{path}: no such file")
    try:
        with can.LogReader(str(p)) as reader:
            for n, msg in enumerate(reader):
                if not msg.is_extended_id and msg.arbitration_id in _IDS:
                    return p
                if n >= PROBE_FRAMES:
                    break
    except Exception as exc:                     # python-can's readers raise anything on a bad file
        raise LogError(f"{path}: not a readable log ({type(exc).__name__}: {exc})") from None
    raise LogError(f"{path}: no frame of this protocol's DBC in it")


class Source(ABC):
    """A thread feeding a BusView; `done` when the source has nothing more."""

    def __init__(self, view: BusView):
        self.view = view
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self.error: str | None = None

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        try:
            self.run()
        except Exception as exc:                 # shown in the footer, never a traceback on screen
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            self.done.set()

    @abstractmethod
    def run(self) -> None:
        """Feed the view until the source ends or `_stop` is set (in the source's thread)."""


class LiveSource(Source):
    """Receives everything on `bus` until stopped (the bus is the caller's to close)."""

    def __init__(self, view: BusView, bus: can.BusABC):
        super().__init__(view)
        self.bus = bus

    def run(self) -> None:
        feed, recv = self.view.feed, self.bus.recv
        while not self._stop.is_set():
            msg = recv(0.1)
            if msg is not None:
                feed(msg.timestamp, msg.arbitration_id, msg.data, msg.is_extended_id)


class ReplaySource(Source):
    """A log at `speed` times its own pace (0: as fast as it can); `lag_s` the most the
    replay fell behind the log's clock (at speed > 0)."""

    def __init__(self, view: BusView, path: Path, speed: float):
        super().__init__(view)
        self.path, self.speed = path, speed
        self.lag_s = 0.0
        self.log_span_s = 0.0
        self.wall_s = 0.0

    def run(self) -> None:
        feed = self.view.feed
        start_wall, first = time.monotonic(), None
        with can.LogReader(str(self.path)) as reader:
            for msg in reader:
                if self._stop.is_set():
                    return
                if first is None:
                    first = msg.timestamp
                if self.speed > 0:
                    due = start_wall + (msg.timestamp - first) / self.speed
                    ahead = due - time.monotonic()
                    if ahead > 0.002:
                        time.sleep(ahead)
                    else:
                        self.lag_s = max(self.lag_s, -ahead)
                feed(msg.timestamp, msg.arbitration_id, msg.data, msg.is_extended_id)
                self.log_span_s = msg.timestamp - first
        self.wall_s = time.monotonic() - start_wall


class CommandSender:
    """HOST_CMD from the operator's keys. It joins the sequence the host on the bus uses:
    the alive counter and SEQ continue from the last HOST_CMD seen, so the controller's E2E
    check takes the monitor's frame as the host's next one."""

    def __init__(self, view: BusView, bus: can.BusABC):
        self.view, self.bus = view, bus
        self.outbox = Outbox("HOST_CMD")
        self.sent: list[tuple[Command, int]] = []

    def send(self, command: Command, argument: int = 0) -> int:
        """Send one command; its SEQ (the CTRL_ACK answering it carries the same)."""
        with self.view.lock:
            counter, seq = self.view.last_host_cmd_counter, (self.view.last_host_cmd_seq + 1) % 256
            self.view.last_host_cmd_seq = seq
        out = self.outbox
        if counter >= 0:                           # protect() advances the counter by one
            out.message.data[1] = (out.message.data[1] & 0xF0) | counter
        v, i = out.values, out.index
        v[i["COMMAND"]], v[i["ARGUMENT"]], v[i["SEQ"]] = int(command), argument, seq
        out.encode()
        self.bus.send(out.message)
        with self.view.lock:
            self.view.last_host_cmd_counter = out.message.data[1] & 0x0F
        # the bus does not echo our own frame: show it as the host's would be shown
        self.view.feed(time.time(), out.message.arbitration_id, bytes(out.message.data))
        self.sent.append((command, seq))
        return seq
