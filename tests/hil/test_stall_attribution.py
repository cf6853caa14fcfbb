"""A fault right after a machine stall is the stall's (`hil.metrics.after_machine_stall`): an
overrun the controller counted, or a long SYNC interval at the recorder, in the 32 cycles
before it. The realtime scenarios and the soak recover from such a fault and count it; any
other fault fails them. Synthetic CTRL_STATUS logs, every 16th cycle as the controller sends."""

import numpy as np
import pytest

from hil.logdata import LogData, Series
from hil.metrics import (
    STALL_WINDOW_CYCLES,
    after_machine_stall,
    fault_transitions,
    faults_in_windows,
    overrun_counts,
    realtime_paced,
    split_faults,
)
from protocol.enums import Fault, State

PERIOD_S = 0.002
N = 1600


def status_log(overrun_at=(), fault_at=None, code=Fault.SENSOR_TIMEOUT, gap_at=None, gap_periods=4.0,
               start_overruns=250, leg_delay_s=None):
    """CTRL_STATUS every 16 cycles; the overrun counter (modulo 256, starting near its wrap)
    steps at each cycle in `overrun_at`; FAULT with `code` from `fault_at` on."""
    cycles = np.arange(0, N, 16)
    overruns = np.array([(start_overruns + sum(1 for c in overrun_at if c <= k)) % 256 for k in cycles])
    state = np.where((fault_at is not None) & (cycles >= (fault_at or 0)), State.FAULT, State.RUNNING)
    fault = np.where(state == State.FAULT, int(code), 0)
    values = np.column_stack([state, fault, overruns]).astype(float)
    sync = np.arange(N) * PERIOD_S
    if gap_at is not None:
        sync[gap_at:] += (gap_periods - 1.0) * PERIOD_S
    status = Series("CTRL_STATUS", cycles, cycles * PERIOD_S, values, {"STATE": 0, "FAULT_CODE": 1, "OVERRUNS": 2})
    series = {"CTRL_STATUS": status}
    if leg_delay_s is not None:        # leg 1's frames: 0.2 ms after each SYNC, some later
        every = np.arange(N)
        delay = np.full(N, 0.2e-3)
        for k, d in leg_delay_s.items():
            delay[k] = d
        series["LEG_STATE_1"] = Series("LEG_STATE_1", every, sync + delay, np.zeros((N, 1)), {"POSITION": 0})
    return LogData("synthetic", N, sync, series, [], 0, {}, {}, 0)


def test_the_overrun_counter_is_unwrapped():
    _, counts = overrun_counts(status_log(overrun_at=range(100, 110)))
    assert counts[0] == 250 and counts[-1] == 260 and np.all(np.diff(counts) >= 0)


def test_a_fault_with_nothing_before_it_is_not_a_stall():
    log = status_log(fault_at=800)
    [(_, cycle, code)] = fault_transitions(log)
    assert code == Fault.SENSOR_TIMEOUT and cycle == 800
    assert not after_machine_stall(log, cycle, PERIOD_S)


@pytest.mark.parametrize("overrun_cycle", [800 - STALL_WINDOW_CYCLES + 8, 790, 800])
def test_a_fault_after_an_overrun_is_the_stall(overrun_cycle):
    log = status_log(overrun_at=[overrun_cycle], fault_at=800)
    assert after_machine_stall(log, 800, PERIOD_S)


def test_an_overrun_long_before_the_fault_does_not_explain_it():
    log = status_log(overrun_at=[600], fault_at=800)
    assert not after_machine_stall(log, 800, PERIOD_S)


@pytest.mark.parametrize("periods, stall", [(4.0, True), (2.5, False)])
def test_a_long_sync_gap_before_the_fault_is_a_stall(periods, stall):
    log = status_log(fault_at=800, gap_at=790, gap_periods=periods)
    assert after_machine_stall(log, 800, PERIOD_S) is stall


@pytest.mark.parametrize("late_s, stall", [(8e-3, True), (1.3e-3, True), (0.5e-3, False)])
def test_sensor_frames_late_after_their_sync_are_a_stall_of_the_nodes(late_s, stall):
    """The emulator not running for ~10 ms: its frames reach the bus in one late burst while
    the controller's SYNCs stay on time (seen in a CI soak: a SENSOR_TIMEOUT with every frame
    in the log)."""
    log = status_log(fault_at=800, leg_delay_s={k: late_s for k in range(785, 790)})
    assert after_machine_stall(log, 800, PERIOD_S) is stall


@pytest.mark.parametrize("lockstep", [False, True])
def test_split_faults_counts_a_stall_only_where_the_syncs_kept_the_period(lockstep):
    """A realtime log: the fault after late sensor frames is the machine's, the one with nothing
    before it is not. The same log paced lockstep (SYNCs as soon as each exchange ends, here
    0.7 ms apart) has no machine stall: both faults are the controller's."""
    log = status_log(fault_at=800, leg_delay_s={k: 8e-3 for k in range(785, 790)})
    if lockstep:
        log.sync_time_s[:] = np.arange(N) * 0.7e-3
    assert realtime_paced(log, PERIOD_S) is not lockstep
    stalls, others = split_faults(log, PERIOD_S)
    expected = [(800, "SENSOR_TIMEOUT")]
    assert (stalls, others) == (([], expected) if lockstep else (expected, []))
    stalls, others = split_faults(status_log(fault_at=800), PERIOD_S)
    assert (stalls, others) == ([], expected)
    stalls, _ = split_faults(status_log(fault_at=800, code=Fault.OVERRUN), PERIOD_S)
    assert stalls == [(800, "OVERRUN")]                  # the stall watchdog itself


def test_faults_in_windows_names_only_an_unexplained_fault_inside_a_window():
    """A repeated start or recovery is judged by the faults in its wall-clock window: one a
    machine stall explains is the machine's, one outside every window is not the window's."""
    fault_s = 800 * PERIOD_S
    plain, stalled = status_log(fault_at=800), status_log(overrun_at=[790], fault_at=800)
    assert faults_in_windows(plain, PERIOD_S, [(fault_s - 0.1, fault_s + 0.1)]) == ["SENSOR_TIMEOUT"]
    assert faults_in_windows(stalled, PERIOD_S, [(fault_s - 0.1, fault_s + 0.1)]) == []
    assert faults_in_windows(plain, PERIOD_S, [(0.0, fault_s - 0.5)]) == []
    assert faults_in_windows(plain, PERIOD_S, []) == []
