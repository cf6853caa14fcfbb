"""Timing of the codec hot path: what one control cycle's frame work costs in Python.

Each case is timed per iteration with `perf_counter_ns`; the figures are percentiles
over many iterations (this machine is shared, so single numbers mean little).
"""

from __future__ import annotations

import gc
import time

import numpy as np

from protocol.codec import CODECS, FrameDecoder

LEGS = range(1, 7)


def _percentiles(samples_ns: np.ndarray) -> dict:
    us = samples_ns / 1e3
    return {"p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max()), "n": int(us.size)}


def run_bench(iterations: int = 20_000) -> dict:
    sensors = [CODECS[f"LEG_STATE_{n}"] for n in LEGS]
    commands = [CODECS[f"VALVE_CMD_{n}"] for n in LEGS]
    decoder = FrameDecoder([c.name for c in sensors])
    expected = decoder.expected_mask(decoder.names)
    rx = {c.name: c.new_buffer() for c in sensors}
    tx = {c.name: c.new_buffer() for c in commands}
    values = {c.name: c.new_values() for c in sensors + commands}

    def receive_one(k):
        c = sensors[0]
        c.encode_into(values[c.name], rx[c.name])        # a fresh frame (sender side, not timed below)
        t0 = time.perf_counter_ns()
        decoder.receive(c.frame_id, rx[c.name])
        return time.perf_counter_ns() - t0

    def encode_one(k):
        c = commands[0]
        values[c.name][6] = (k % 200 - 100) / 100
        t0 = time.perf_counter_ns()
        c.encode_into(values[c.name], tx[c.name])
        return time.perf_counter_ns() - t0

    def cycle(k):
        for c in sensors:
            c.encode_into(values[c.name], rx[c.name])
        t0 = time.perf_counter_ns()
        decoder.begin_cycle()
        for c in sensors:
            decoder.receive(c.frame_id, rx[c.name])
        decoder.end_cycle(expected)
        for c in commands:
            c.encode_into(values[c.name], tx[c.name])
        return time.perf_counter_ns() - t0

    results = {}
    gc_was_enabled = gc.isenabled()
    gc.collect()
    gc.disable()                       # as the control loop will run
    try:
        for name, case in (("receive_leg_state", receive_one), ("encode_valve_cmd", encode_one),
                           ("cycle_6_receive_6_encode", cycle)):
            for k in range(min(1000, iterations)):        # warm-up
                case(k)
            samples = np.fromiter((case(k) for k in range(iterations)), dtype=np.float64, count=iterations)
            results[name] = _percentiles(samples)
    finally:
        if gc_was_enabled:
            gc.enable()
    return {"iterations": iterations, "cases": results}


def format_bench(result: dict) -> str:
    lines = [f"{'case':<28} {'p50 us':>8} {'p99 us':>8} {'max us':>8}"]
    for name, r in result["cases"].items():
        lines.append(f"{name:<28} {r['p50_us']:>8.2f} {r['p99_us']:>8.2f} {r['max_us']:>8.2f}")
    lines.append(f"({result['iterations']} iterations each)")
    return "\n".join(lines)
