"""`hydrapod protocol sync-check`: the kernel's SYNC on a SocketCAN interface, as the
controller starts it (`firmware_py/runtime/sync.BusSync`: the broadcast manager repeating the
counter sequence), received back and judged from the frames' kernel receive stamps: every
counter in order, and the period's error (a benchmark: the interface's and kernel's timing,
not Python's)."""

from __future__ import annotations

import time

import numpy as np

from firmware_py.runtime.sync import BusSync
from program.realtime import percentiles_us
from protocol.codec import STANDARD_ID_MASK


def sync_check(bus, rate_hz: float, seconds: float, overflow: int) -> dict:
    """Start the bus's SYNC at `rate_hz` for `seconds`, receive it on the same bus: counts,
    counter gaps and the receive stamps' period error (us percentiles)."""
    period_s = 1.0 / rate_hz
    source = BusSync(bus, period_s, overflow)
    bus.set_filters([{"can_id": source.frame_id, "can_mask": STANDARD_ID_MASK, "extended": False}])
    stamps, counters = [], []
    source.start()
    try:
        end = time.monotonic() + seconds
        while (remaining := end - time.monotonic()) > 0.0:
            msg = bus.recv(timeout=remaining)
            if msg is not None and msg.dlc >= 1:          # the filter passes only the SYNC
                stamps.append(msg.timestamp)
                counters.append(msg.data[0])
    finally:
        source.stop()
    gaps = sum(1 for a, b in zip(counters, counters[1:]) if b != a % overflow + 1)
    error = np.abs(np.diff(np.asarray(stamps)) - period_s)
    return {"rate_hz": rate_hz, "seconds": seconds, "syncs": len(counters), "expected": int(seconds * rate_hz),
            "first_counter": counters[0] if counters else None, "counter_gaps": gaps,
            "period_error_us": percentiles_us(error) if len(error) else {},
            "passed": len(counters) >= 2 and gaps == 0}


def format_sync_check(doc: dict) -> str:
    e = doc["period_error_us"]
    timing = f"period error p50 {e['p50']:.0f} us, p99 {e['p99']:.0f} us, max {e['max']:.0f} us" if e else "no period"
    return (f"SYNC at {doc['rate_hz']:g} Hz for {doc['seconds']:g} s: {doc['syncs']} received "
            f"(~{doc['expected']} sent), {doc['counter_gaps']} counter gaps; {timing} "
            f"({'pass' if doc['passed'] else 'FAIL'})")
