"""The emulator's own timing: kernels loaded before the first SYNC, and node clocks that stand
still while the emulator process is not scheduled (host stalls), without hiding a controller
that really went silent."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from plant_emulator.emulator import FAULT_ONSET_EVENT, Emulator
from plant_emulator.params import load_config
from plant_emulator.process import run
from plant_emulator.rigs import make_rig
from protocol.outbox import Outbox
from tests.support.buses import ScriptedBus, sync_frame

PERIOD_S = 0.002


@pytest.fixture(scope="module")
def cfg():
    return load_config()


@pytest.mark.parametrize("rig_name", ["testbench", "hexapod"])
def test_warm_up_leaves_the_rig_untouched(cfg, rig_name):
    rig = make_rig(rig_name, cfg)
    rig.command[:] = 0.3
    state, time_s, force = rig.state.copy(), rig.time_s, rig.rod_force_n.copy()
    rig.warm_up()
    np.testing.assert_array_equal(rig.state, state)
    np.testing.assert_array_equal(rig.rod_force_n, force)
    assert rig.time_s == time_s
    # and it did not change what the next step computes
    twin = copy.deepcopy(rig) if rig_name == "testbench" else None
    if twin is not None:
        rig.advance(PERIOD_S)
        twin.advance(PERIOD_S)
        np.testing.assert_array_equal(rig.state, twin.state)


def run_script(cfg, script) -> Emulator:
    """Until the script ends or the SYNC watchdog fires."""
    bus = ScriptedBus(script)
    emulator = Emulator(bus, make_rig("testbench", cfg), cfg, clock=bus.clock)
    run(emulator, bus, lambda: not bus.script or emulator.sync_lost_reported)
    return emulator


def test_a_host_stall_does_not_read_as_a_lost_sync(cfg):
    stall_s = 10 * PERIOD_S                          # > the 3-period watchdog
    emulator = run_script(cfg, [("frame", sync_frame(1)), ("stall", stall_s), ("frame", sync_frame(2)),
                                ("quiet",)])
    assert emulator.counters.syncs == 2
    assert emulator.counters.host_stalls == 1
    assert emulator.counters.host_stall_max_s == pytest.approx(stall_s)
    assert not emulator.sync_lost_reported


def test_a_silent_controller_still_trips_the_watchdog(cfg):
    # the same 20 ms without SYNC, but this process was awake the whole time
    script = [("frame", sync_frame(1))] + [("quiet",)] * 40
    emulator = run_script(cfg, script)
    assert emulator.counters.host_stalls == 0
    assert emulator.sync_lost_reported
    watchdog_s = cfg.nodes.sync_timeout_periods * PERIOD_S
    assert watchdog_s < emulator.clock() - emulator.last_sync_time <= watchdog_s + PERIOD_S


def valve_command_frames(box, n):
    """n VALVE_CMD_1 frames from one sender (its alive counter running)."""
    frames = []
    for _ in range(n):
        assert box.encode()
        frames.append(("frame", copy.deepcopy(box.message)))
    return frames


def nmt_start_frame():
    box = Outbox("NMT")
    box.values[:] = (1, 0)                                   # start, all nodes
    assert box.encode()
    return ("frame", copy.deepcopy(box.message))


def test_a_restarted_controller_is_not_an_e2e_error_for_the_valves(cfg):
    first, second = Outbox("VALVE_CMD_1"), Outbox("VALVE_CMD_1")    # two controller processes
    script = ([nmt_start_frame()] + valve_command_frames(first, 7)
              + [nmt_start_frame()] + valve_command_frames(second, 3) + [("quiet",)])
    emulator = run_script(cfg, script)
    assert emulator.counters.e2e_errors == 0
    # without the NMT start in between, the same restart is caught
    emulator = run_script(cfg, [nmt_start_frame()] + valve_command_frames(Outbox("VALVE_CMD_1"), 7)
                          + valve_command_frames(Outbox("VALVE_CMD_1"), 3) + [("quiet",)])
    assert emulator.counters.e2e_errors >= 1


def test_the_plant_runs_on_after_the_sync_is_lost(cfg):
    """A dead controller does not freeze the mechanism: after the watchdog, physics runs on
    the wall clock with the valves in FAULT_HOLD (what the fault matrix measures)."""
    quiet = 100                                               # 0.5 ms polls: 50 ms without SYNC
    bus = ScriptedBus([nmt_start_frame(), ("frame", sync_frame(1))] + [("quiet",)] * quiet)
    sent = []
    bus.send = sent.append
    emulator = Emulator(bus, make_rig("testbench", cfg), cfg, clock=bus.clock)
    run(emulator, bus, lambda: not bus.script)
    assert emulator.sync_lost_reported
    elapsed = emulator.clock() - emulator.last_sync_time
    # one period at the SYNC, then every period up to now (within one period of polling)
    assert abs(emulator.rig.time_s - elapsed) <= 2 * PERIOD_S
    assert emulator.counters.free_run_steps >= int(elapsed / PERIOD_S) - 2
    truth = [m for m in sent if m.arbitration_id == Outbox("EMU_TRUTH").codec.frame_id]
    assert len(truth) == 1 + emulator.counters.free_run_steps
    assert emulator.rig.command[0] == 0.0                     # no valve left open


def test_repeat_resends_the_previous_frame_and_leg_jam_seizes_the_rod(cfg):
    bus = ScriptedBus([])
    sent = []
    bus.send = sent.append
    emulator = Emulator(bus, make_rig("testbench", cfg), cfg, clock=bus.clock)
    emulator.nmt[1] = 5
    leg_state = Outbox("LEG_STATE_1").codec.frame_id
    frames = lambda: [bytes(m.data) for m in sent if m.arbitration_id == leg_state]  # noqa: E731
    emulator.on_sync(1)
    before = frames()[-1]
    emulator._emu_ctrl(2, 1, 12, 0.0, 0)                      # INJECT REPEAT on leg 1
    emulator.on_sync(2)
    emulator.on_sync(3)
    assert frames()[-2:] == [before, before]                  # the same counter and CRC again
    emulator._emu_ctrl(3, 1, 12, 0.0, 0)                      # CLEAR
    emulator.on_sync(4)
    assert frames()[-1] != before
    emulator._emu_ctrl(2, 1, 13, 0.0, 0)                      # INJECT LEG_JAM
    y0 = emulator.rig.stroke_m[0]
    emulator.rig.command[0] = 0.3
    emulator.rig.advance(0.2)
    assert emulator.rig.stroke_m[0] == y0


def test_an_injection_reports_its_onset_at_the_first_sync_that_sees_it(cfg, capsys):
    """The host's EMU_CTRL and the controller's SYNC race to the emulator: the onset the fault
    matrix judges from is the SYNC the emulator handled first after the fault, not the log's."""
    bus = ScriptedBus([])
    emulator = Emulator(bus, make_rig("testbench", cfg), cfg, clock=bus.clock)
    emulator.on_sync(7)
    assert emulator.counters.fault_onsets == []
    emulator._emu_ctrl(2, 1, 13, 0.0, 0)                      # INJECT LEG_JAM on leg 1
    emulator.on_sync(8)
    emulator.on_sync(9)
    (onset,) = emulator.counters.fault_onsets
    assert (onset["target"], onset["fault"], onset["sync_counter"]) == (1, "LEG_JAM", 8)
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith(FAULT_ONSET_EVENT) and json.loads(line[len(FAULT_ONSET_EVENT):]) == onset
