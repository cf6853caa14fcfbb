"""The realtime process set-up (program.realtime): each measure is applied, or its reason is
returned for the process to log; none is fatal."""

from __future__ import annotations

import gc
import subprocess
import sys

from program import realtime


def test_freeze_gc_freezes_and_disables_and_thaw_restores():
    assert gc.isenabled()
    try:
        realtime.freeze_gc(disable=True)
        assert not gc.isenabled() and gc.get_freeze_count() > 0
    finally:
        realtime.thaw_gc()
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_memory_is_not_locked_under_a_finite_limit_and_says_why(monkeypatch):
    monkeypatch.setattr(realtime, "_lock_unlimited", lambda: False)
    problem = realtime.lock_memory()
    assert problem is not None and "RLIMIT_MEMLOCK" in problem


def test_a_refused_scheduling_policy_is_a_reason_not_an_exception():
    problem = realtime.set_fifo(10_000)                 # no such priority
    assert problem is not None and "SCHED_FIFO not permitted" in problem


def test_the_emulator_applies_each_measure_or_logs_why_not():
    code = ("import os; from plant_emulator.params import load_config; from plant_emulator.process import "
            "realtime_setup; print(realtime_setup(load_config()), os.sched_getscheduler(0) == os.SCHED_FIFO, "
            "os.sched_getparam(0).sched_priority)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    notes, log = proc.stdout, proc.stderr
    if "SCHED_FIFO priority 70" in notes:                # below the controller's 80
        assert notes.strip().endswith("True 70"), notes
    else:
        assert "SCHED_FIFO not permitted" in log, (notes, log)
    assert "mlockall" in notes or "memory not locked" in log or "mlockall" in log, (notes, log)
    assert "CPU wake-up latency <= 0 us" in notes or "CPU wake-up latency not requested" in log, (notes, log)


def test_the_controller_daemon_applies_each_measure_or_logs_why_not():
    code = ("from firmware_py.config import load_config; from firmware_py.runtime.daemon import realtime_setup; "
            "print(realtime_setup(load_config(), True))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    notes, log = proc.stdout, proc.stderr
    assert "SCHED_FIFO priority" in notes or "SCHED_FIFO not permitted" in log, (notes, log)
    assert "mlockall" in notes or "memory not locked" in log or "mlockall" in log, (notes, log)
    assert "CPU wake-up latency <= 0 us" in notes or "CPU wake-up latency not requested" in log, (notes, log)


def test_a_lockstep_controller_asks_for_the_cpu_latency_alone():
    """Lockstep: no realtime scheduling or memory locking, but the wake-up latency request
    (each cycle waits on the other process's frames), applied or logged."""
    code = ("from firmware_py.config import load_config; from firmware_py.runtime.daemon import realtime_setup; "
            "print(realtime_setup(load_config(), False))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    notes, log = proc.stdout, proc.stderr
    assert "SCHED_FIFO" not in notes + log and "mlockall" not in notes + log, (notes, log)
    assert "CPU wake-up latency <= 0 us" in notes or "CPU wake-up latency not requested" in log, (notes, log)


def test_the_cpu_latency_request_is_written_and_held_or_says_why(tmp_path):
    """The PM QoS request is the value written to the device, kept open for the process's
    life; a device that cannot be opened is a reason, not an exception."""
    import os
    import struct
    target = tmp_path / "cpu_dma_latency"
    target.write_bytes(b"")
    assert realtime.request_cpu_latency(0, str(target)) is None
    assert struct.unpack("i", target.read_bytes()) == (0,)
    held = realtime._latency_fd
    assert held is not None and os.fstat(held).st_ino == target.stat().st_ino
    problem = realtime.request_cpu_latency(0, str(tmp_path / "missing"))
    assert problem is not None and "not requested" in problem and realtime._latency_fd == held
