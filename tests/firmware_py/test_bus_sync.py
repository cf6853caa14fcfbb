"""The SYNC from the bus's periodic sender ([timing] sync_source, runtime/sync.py): the
sequence it repeats, when the loop uses it, and how the loop follows it (a late SYNC
skipped, a missing one a stall, the counter the bus's)."""

from __future__ import annotations

import time

import can
import cantools
import pytest
from can.interfaces.socketcan import SocketcanBus

from firmware_py.config import ConfigError, load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime import loop as loop_module
from firmware_py.runtime.loop import ControllerLoop
from firmware_py.runtime.sync import bus_sends_sync, check_sync_source, sync_sequence
from program.errors import UserInputError
from protocol.dbc import dbc_path, sync_counter_overflow
from tests.support.cli import hydrapod

PERIOD_S = 0.002


def test_the_sequence_is_every_counter_once_as_stock_cantools_decodes_it():
    overflow = sync_counter_overflow()
    frames = sync_sequence(overflow)
    db = cantools.database.load_file(str(dbc_path()))
    sync = db.get_message_by_name("SYNC")
    assert [db.decode_message(f.arbitration_id, f.data)["COUNTER"] for f in frames] == list(range(1, overflow + 1))
    assert all(f.arbitration_id == sync.frame_id and len(f.data) == sync.length for f in frames)


def test_auto_is_the_bus_on_socketcan_in_realtime_only():
    socketcan = object.__new__(SocketcanBus)                 # the type decides; no kernel CAN here
    virtual = can.Bus(interface="virtual", channel="sync-choice")
    try:
        assert bus_sends_sync("auto", "realtime", socketcan)
        assert bus_sends_sync("bus", "realtime", socketcan)
        assert not bus_sends_sync("auto", "lockstep", socketcan)
        assert not bus_sends_sync("auto", "realtime", virtual)
        assert not bus_sends_sync("loop", "realtime", socketcan)
    finally:
        virtual.shutdown()


def test_a_source_the_pacing_or_bus_cannot_use_is_one_line_naming_the_key():
    with pytest.raises(UserInputError, match=r"\[timing\]\.sync_source = \"bus\" needs --pacing realtime"):
        check_sync_source("bus", "lockstep", True)
    # elsewhere python-can sends periodic frames from the bus's own thread, which it never receives
    with pytest.raises(UserInputError, match=r"\[timing\]\.sync_source = \"bus\" needs a SocketCAN bus"):
        check_sync_source("bus", "realtime", False)
    with pytest.raises(ConfigError, match="sync_source = 'kernel': must be one of auto, loop, bus"):
        load_config(overrides={"timing": {"sync_source": "kernel"}})


def test_the_daemon_refuses_the_bus_sync_in_lockstep(tmp_path):
    config = tmp_path / "bus-sync.toml"
    config.write_text('[timing]\nsync_source = "bus"\n')
    proc = hydrapod("controller", "--pacing", "lockstep", "--bus", "virtual:refused", "--config", config)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "sync_source" in lines[0], proc.stderr


class WallClock:
    """The loop's `time` module with its wall clock held at the scripted bus's last receive: a
    frame's age (now minus its receive stamp) is then the age scripted, however long the
    machine took between the receive and the loop's look at it (a 2-core machine busy with
    the suite's other worker stalled longer than the sync window, and a fresh SYNC read as late)."""

    def __init__(self):
        self.now = time.time()

    def time(self) -> float:
        return self.now

    def __getattr__(self, name):
        return getattr(time, name)


WALL = WallClock()


@pytest.fixture(autouse=True)
def _held_wall_clock(monkeypatch):
    monkeypatch.setattr(loop_module, "time", WALL)


class ScriptedBus(SocketcanBus):
    """A SocketCAN bus by type, scripted (no kernel CAN here): frames queued as (frame, age in s
    when received, on `WALL`); `send_periodic` only recorded."""

    def __init__(self):
        can.BusABC.__init__(self, channel="scripted")
        self.queue: list[tuple[can.Message, float]] = []
        self.periodic: list = []

    def sync(self, counter: int, age_s: float = 0.0) -> None:
        self.queue.append((sync_sequence(counter)[-1], age_s))

    def frame(self, frame_id: int) -> None:
        self.queue.append((can.Message(arbitration_id=frame_id, data=bytes(8), is_extended_id=False), 0.0))

    def _recv_internal(self, timeout):
        if not self.queue:
            time.sleep(min(timeout or 0.0, 0.001))
            return None, False
        msg, age = self.queue.pop(0)
        WALL.now = time.time()
        msg.timestamp = WALL.now - age
        return msg, False

    def send(self, msg, timeout=None) -> None:
        pass

    def shutdown(self) -> None:
        can.BusABC.shutdown(self)

    def _apply_filters(self, filters) -> None:       # python-can checks them again on receive
        pass

    def _send_periodic_internal(self, msgs, period, duration=None, autostart=True, modifier_callback=None):
        self.periodic.append((list(msgs), period))
        return _Task()


class _Task:
    def stop(self) -> None:
        pass


def _loop(bus) -> ControllerLoop:
    cfg = load_config(overrides={"timing": {"sync_source": "bus"}})
    ctl = Controller(cfg, "testbench", PERIOD_S, CONTROLLER_NAMES["pi"])
    return ControllerLoop(bus, ctl, 1.0 / PERIOD_S, "realtime", log=lambda _: None)


def test_the_loop_starts_the_sequence_once_and_listens_for_the_sync():
    bus = ScriptedBus()
    loop = _loop(bus)
    assert {"can_id": 0x80, "can_mask": 0x7FF, "extended": False} in loop.can_filters()
    loop.bus_sync.start()
    loop.bus_sync.start()
    [(frames, period)] = bus.periodic
    assert period == PERIOD_S and [f.data[0] for f in frames] == list(range(1, sync_counter_overflow() + 1))
    assert loop.summary()["sync_source"] == "bus"


def test_the_cycle_takes_the_buses_counter_and_its_time_from_the_receive_stamp():
    bus = ScriptedBus()
    loop = _loop(bus)
    bus.frame(0x7FF)                                  # a frame before the SYNC is handled, not taken
    bus.sync(7, age_s=0.0004)
    before = loop.clock()
    sync_at = loop._await_sync()
    assert loop.sync_counter == 7 and not loop._overrun
    assert before - 0.05 < sync_at <= loop.clock() - 0.0004            # when it was sent, not taken
    assert loop.stats.unknown_frames == 1 and loop.stats.frames_sent == 1


def test_a_sync_taken_after_the_window_is_skipped_as_an_overrun_never_a_burst():
    bus = ScriptedBus()
    loop = _loop(bus)
    window = loop.cfg.timing.sync_window_fraction * PERIOD_S
    bus.sync(1)
    loop._await_sync()
    bus.sync(2, age_s=window + 0.0005)                # the process was late: SYNC 2's samples are gone
    bus.sync(3, age_s=0.0001)
    loop._await_sync()
    assert loop.sync_counter == 3 and loop._overrun
    assert loop.stats.overruns == 1 and loop.stats.syncs_skipped == 1
    bus.sync(4)
    loop._await_sync()
    assert not loop._overrun and loop.stats.syncs_skipped == 1


def test_lost_syncs_are_counted_from_the_counter():
    bus = ScriptedBus()
    loop = _loop(bus)
    bus.sync(239)
    loop._await_sync()
    bus.sync(3)                                       # 240, 1 and 2 never arrived (wraps at 240)
    loop._await_sync()
    assert loop.sync_counter == 3 and loop.stats.syncs_skipped == 3


def test_no_sync_within_the_stall_limit_is_a_stall_and_the_cycle_runs_without_it():
    bus = ScriptedBus()
    loop = _loop(bus)
    bus.sync(5)
    loop._last_sync = loop._await_sync()
    returned = loop._await_sync()
    limit = loop.cfg.timing.stall_fault_periods * PERIOD_S
    assert loop._stalled and loop.stats.syncs_missing == 1 and loop.sync_counter == 5
    assert limit <= returned - loop._last_sync < limit + 0.05


def test_sync_check_refuses_a_bus_without_the_kernels_sync():
    proc = hydrapod("protocol", "sync-check", "--bus", "udp_multicast:239.255.72.99")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "needs a SocketCAN interface" in lines[0], proc.stderr
