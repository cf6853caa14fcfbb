"""Process set-up for realtime pacing, shared by the bus nodes (controller, emulator) and the
host's recorder. Once a process's start-up is over: its start-up objects are frozen out of
the garbage collector (a collection then scans only what the run created, not the whole
heap of NumPy, SciPy and MuJoCo objects), its memory is locked (no page fault in the loop),
it may run SCHED_FIFO and pinned to a CPU, and it asks that idle CPUs wake within a bound.
A measure that is not permitted returns the reason, for the process to log; none of them is
fatal. And the one summary of a loop's duration records (percentiles in us).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import resource
import struct

import numpy as np

from program.sections import Key

MCL_CURRENT, MCL_FUTURE = 1, 2
# the keys every process's [timing] or [nodes] table has for these measures
REALTIME_PRIORITY = Key("realtime_priority", 1, 99)              # SCHED_FIFO, when permitted
CPU_LATENCY = Key("cpu_latency_us", -1, 100000)                    # PM QoS wake-up latency; -1: ask nothing


def freeze_gc(disable: bool) -> None:
    """Collect once, freeze what is left; `disable`: no automatic collection at all (for a
    loop that creates no reference cycles, as the controller's cycle does not)."""
    gc.collect()
    gc.freeze()
    if disable:
        gc.disable()


def thaw_gc() -> None:
    gc.enable()
    gc.unfreeze()


CAP_IPC_LOCK = 14


def _lock_unlimited() -> bool:
    """Whether this process may lock any amount: CAP_IPC_LOCK, or an unlimited RLIMIT_MEMLOCK
    (raised to its hard limit first)."""
    try:
        with open("/proc/self/status") as status:
            caps = next((line.split()[1] for line in status if line.startswith("CapEff:")), "0")
        if int(caps, 16) >> CAP_IPC_LOCK & 1:
            return True
    except OSError:
        pass
    soft, hard = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if soft != hard:
        try:
            resource.setrlimit(resource.RLIMIT_MEMLOCK, (hard, hard))
            soft = hard
        except (OSError, ValueError):
            pass
    return soft == resource.RLIM_INFINITY


def lock_memory() -> str | None:
    """mlockall, current and future pages; None when done, else why not. Only where any amount
    may be locked: under a finite limit an allocation past it would fail."""
    if not _lock_unlimited():
        soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
        return f"memory not locked: RLIMIT_MEMLOCK is {soft} bytes and no CAP_IPC_LOCK (ulimit -l unlimited)"
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            return f"mlockall not permitted ({os.strerror(ctypes.get_errno())}); memory may page"
    except (OSError, AttributeError) as exc:
        return f"mlockall unavailable ({exc})"
    return None


def set_fifo(priority: int) -> str | None:
    """SCHED_FIFO at `priority` for this process; None when done, else why not."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"SCHED_FIFO not permitted ({exc}); running with normal scheduling"
    return None


def pin_cpu(cpu: int) -> str | None:
    try:
        os.sched_setaffinity(0, {cpu})
    except (OSError, AttributeError) as exc:
        return f"CPU affinity {cpu} not permitted ({exc})"
    return None


CPU_LATENCY_PATH = "/dev/cpu_dma_latency"
_latency_fd: int | None = None          # the request lasts while this stays open


def request_cpu_latency(latency_us: int, path: str = CPU_LATENCY_PATH) -> str | None:
    """PM QoS: ask the kernel to keep every CPU's wake-up latency within `latency_us` for the
    rest of this process's life (0: no idle state deeper than polling, as cyclictest asks).
    A halted virtual CPU waits for its hypervisor to run it again when woken; on this kind of
    machine that was most of the 500 Hz loops' overruns (docs/TIMING.md). None when done,
    else why not."""
    global _latency_fd
    try:
        fd = os.open(path, os.O_WRONLY)
        try:
            os.write(fd, struct.pack("i", latency_us))
        except OSError:
            os.close(fd)
            raise
    except OSError as exc:
        return f"CPU wake-up latency not requested ({path}: {exc.strerror}); idle CPUs may halt"
    if _latency_fd is not None:
        os.close(_latency_fd)
    _latency_fd = fd
    return None


def cpu_latency_measure(latency_us: int) -> dict[str, str | None]:
    """The request as a measure for `applied` ({} for -1: ask nothing)."""
    if latency_us < 0:
        return {}
    return {f"CPU wake-up latency <= {latency_us} us": request_cpu_latency(latency_us)}


def applied(measures: dict[str, str | None], log) -> list[str]:
    """{measure: None when done, else why not}: `log` each reason; the names of those done."""
    for problem in measures.values():
        if problem:
            log(problem)
    return [name for name, problem in measures.items() if problem is None]


def percentiles_us(seconds) -> dict:
    """p50, p99 and max of a record of durations in seconds, in us (the loops' timing summaries)."""
    p50, p99 = np.percentile(seconds, [50, 99]) * 1e6
    return {"p50": round(float(p50), 1), "p99": round(float(p99), 1), "max": round(float(np.max(seconds)) * 1e6, 1)}
