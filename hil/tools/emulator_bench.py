"""`hydrapod emulator bench`: simulated seconds per wall second of each rig at a SYNC rate.

Each SYNC runs what the emulator process runs (`Emulator.on_sync`: sensor sampling and
frame encoding for every node, the valve state machines, one SYNC period of physics) with
the bus replaced by nothing, after a warm-up that compiles the numba kernels.
"""

from __future__ import annotations

import time

import numpy as np

from plant_emulator.emulator import Emulator
from plant_emulator.params import EmulatorConfig, build, merge
from plant_emulator.rigs import make_rig
from protocol.enums import NmtState

GOALS = {"testbench": 10.0, "hexapod": 3.0}


def bench_rig(name: str, cfg: EmulatorConfig, seconds: float, rate_hz: float) -> dict:
    period = 1.0 / rate_hz
    cfg = build(merge(cfg.raw, {"nodes": {"sync_period_ms": period * 1e3}}, "the bench"))
    rig = make_rig(name, cfg)
    emulator = Emulator(None, rig, cfg)
    emulator.boot()
    for n in emulator.nmt:
        emulator.nmt[n] = NmtState.OPERATIONAL
    for valve in emulator.valves.values():   # hold, then active with a small sine command
        valve.receive(True, True, False, False, 0.0)
        valve.on_sync()
    syncs = max(1, round(seconds * rate_hz))
    warmup = min(50, syncs)
    wall = np.empty(syncs)
    for k in range(warmup + syncs):
        for valve in emulator.valves.values():
            valve.receive(True, True, True, False, 0.05 * np.sin(2 * np.pi * k * period))
        start = time.perf_counter()
        emulator.on_sync(k % 240 + 1)
        if k >= warmup:
            wall[k - warmup] = time.perf_counter() - start
    total = float(wall.sum())
    return {"rig": name, "rate_hz": rate_hz, "simulated_s": syncs * period, "wall_s": total,
            "realtime_factor": syncs * period / total, "goal": GOALS[name],
            "per_sync_us": {"p50": float(np.percentile(wall, 50) * 1e6), "p99": float(np.percentile(wall, 99) * 1e6),
                            "max": float(wall.max() * 1e6)}}


def format_bench(rows: list[dict]) -> str:
    lines = ["rig        rate    sim s   wall s   x realtime  goal   per SYNC p50/p99/max [us]"]
    for r in rows:
        p = r["per_sync_us"]
        lines.append(f"{r['rig']:<10} {r['rate_hz']:>4.0f} Hz {r['simulated_s']:6.2f} {r['wall_s']:8.3f} "
                     f"{r['realtime_factor']:10.1f}  >={r['goal']:<4g} {p['p50']:.0f}/{p['p99']:.0f}/{p['max']:.0f}")
    return "\n".join(lines)
