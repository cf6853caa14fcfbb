"""Bus budget computed from the DBC: per-frame bits, average load, and the cycle timeline.

Classic CAN, 11-bit id, N data bytes. Nominal bits: 44 + 8N frame bits + 3 interframe
space = 8N + 47. Worst case with bit stuffing (one stuff bit per 4 bits over the 34 + 8N
stuffable bits): 8N + 47 + floor((34 + 8N - 1) / 4), i.e. 135 bits for 8 bytes.

Load: SYNC-driven frames count 1/n of their bits per SYNC, timer frames (heartbeats)
count at their own rate; event frames (EMCY, host commands, acks) are not periodic and are
covered by the blocking allowance instead.

Timeline of one cycle (the worst over the schedule's hyper-period, i.e. the cycle in which
the most SYNC-driven bits are due): SYNC -> every sensor frame due -> controller compute
-> every controller frame due (valve commands, CTRL_STATUS when due). Its free time is
`compute_window_us`. Because CAN does not pre-empt a frame in progress, a sporadic frame
that started just before the commands delays them by up to one longest frame:
`compute_window_with_blocking_us` subtracts that too.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from protocol.dbc import CONTROLLER_NODE, Schedule, schedules, sync_counter_overflow

MAX_LOAD = 0.80
MIN_COMPUTE_WINDOW_US = 400.0
# the controller's cycle compute budget (p99, `controller bench`): the window a sporadic frame
# blocking the commands leaves must still hold it
COMPUTE_BUDGET_US = 300.0


def frame_bits_nominal(n_bytes: int) -> int:
    return 8 * n_bytes + 47


def frame_bits_worst(n_bytes: int) -> int:
    return 8 * n_bytes + 47 + (34 + 8 * n_bytes - 1) // 4


@dataclass(frozen=True)
class FrameLoad:
    name: str
    id: int
    dlc: int
    sender: str
    kind: str                     # cyclic | every_nth_sync | timer | event
    bits_worst: int
    bits_nominal: int
    period_cycles: float | None   # SYNC periods between two frames; None for event frames
    sync_phase: int | None


def frame_loads(rate_hz: float, scheds: tuple[Schedule, ...] | None = None) -> list[FrameLoad]:
    out = []
    for s in scheds or schedules():
        if s.sync_period:
            period = float(s.sync_period)
        elif s.cycle_time_ms:
            period = s.cycle_time_ms * 1e-3 * rate_hz
        else:
            period = None
        out.append(FrameLoad(
            name=s.name, id=s.frame_id, dlc=s.dlc, sender=s.sender, kind=s.kind,
            bits_worst=frame_bits_worst(s.dlc), bits_nominal=frame_bits_nominal(s.dlc),
            period_cycles=period, sync_phase=s.sync_phase if s.sync_period else None,
        ))
    return out


def _cycle_frames(scheds, slot: int):
    """SYNC-driven frames due in the cycle whose SYNC counter is slot + 1."""
    return [s for s in scheds if s.sync_period and s.due(slot + 1)]


def bus_budget(rate_hz: float, bitrate: float, *, max_load: float = MAX_LOAD,
               min_compute_us: float = MIN_COMPUTE_WINDOW_US, scheds: tuple[Schedule, ...] | None = None) -> dict:
    """The whole budget as a JSON-ready dict (see module docstring for the model) of the
    DBC's schedule, or of `scheds` (another layout's frames, `protocol.canopen_layout`)."""
    if not rate_hz > 0 or not bitrate > 0:
        raise ValueError("rate_hz and bitrate must be > 0")
    scheds = scheds or schedules()
    loads = frame_loads(rate_hz, scheds)
    bit_us = 1e6 / bitrate
    period_us = 1e6 / rate_hz

    periodic = [f for f in loads if f.period_cycles]
    bits_per_cycle_worst = sum(f.bits_worst / f.period_cycles for f in periodic)
    bits_per_cycle_nominal = sum(f.bits_nominal / f.period_cycles for f in periodic)
    total_load = bits_per_cycle_worst * bit_us / period_us
    nominal_load = bits_per_cycle_nominal * bit_us / period_us

    overflow = sync_counter_overflow()
    hyper = math.lcm(*(s.sync_period for s in scheds if s.sync_period))
    if overflow % hyper:
        raise ValueError(f"SYNC periods (hyper-period {hyper}) do not divide the counter overflow {overflow}")

    def cycle(slot: int) -> dict:
        due = _cycle_frames(scheds, slot)
        sync = [s for s in due if s.name == "SYNC"]
        sensors = [s for s in due if s.sender != CONTROLLER_NODE]
        commands = [s for s in due if s.sender == CONTROLLER_NODE and s.name != "SYNC"]
        bits = {k: sum(frame_bits_worst(s.dlc) for s in v)
                for k, v in (("sync", sync), ("sensors", sensors), ("commands", commands))}
        return {"slot": slot, "frames": [s.name for s in due], **{f"{k}_bits": v for k, v in bits.items()},
                "bus_bits": sum(bits.values())}

    cycles = [cycle(slot) for slot in range(hyper)]
    worst = max(cycles, key=lambda c: c["bus_bits"])
    blocking_bits = max((f.bits_worst for f in loads if f.kind in ("event", "timer")), default=0)
    compute_window_us = period_us - worst["bus_bits"] * bit_us
    compute_window_blocking_us = compute_window_us - blocking_bits * bit_us

    t_sensors_done = (worst["sync_bits"] + worst["sensors_bits"]) * bit_us
    timeline = [
        {"phase": "sync", "start_us": 0.0, "end_us": worst["sync_bits"] * bit_us},
        {"phase": "sensor_frames", "start_us": worst["sync_bits"] * bit_us, "end_us": t_sensors_done},
        {"phase": "compute", "start_us": t_sensors_done, "end_us": t_sensors_done + compute_window_us},
        {"phase": "command_frames", "start_us": t_sensors_done + compute_window_us, "end_us": period_us},
    ]
    fits = total_load <= max_load and compute_window_us >= min_compute_us
    return {
        "rate_hz": rate_hz,
        "bitrate": bitrate,
        "period_us": period_us,
        "total_load": total_load,
        "nominal_load": nominal_load,
        "compute_window_us": compute_window_us,
        "compute_window_with_blocking_us": compute_window_blocking_us,
        "blocking_bits": blocking_bits,
        "hyper_period_cycles": hyper,
        "worst_cycle": worst,
        "timeline": timeline,
        "limits": {"max_load": max_load, "min_compute_window_us": min_compute_us},
        "fits": fits,
        "messages": [asdict(f) for f in loads],
    }


def format_budget(budget: dict) -> str:
    """Human-readable table of `bus_budget`'s result."""
    lines = [f"{'message':<20} {'id':>5} {'dlc':>3} {'kind':<15} {'bits worst':>10} {'every':>10}"]
    for m in budget["messages"]:
        every = "event" if m["period_cycles"] is None else f"{m['period_cycles']:g} SYNC"
        lines.append(f"{m['name']:<20} {m['id']:>#5x} {m['dlc']:>3} {m['kind']:<15} {m['bits_worst']:>10} {every:>10}")
    w = budget["worst_cycle"]
    lim = budget["limits"]
    lines += [
        "",
        f"rate {budget['rate_hz']:g} Hz, bitrate {budget['bitrate']:g} bit/s, period {budget['period_us']:.1f} us",
        f"load: worst case (bit-stuffed) {budget['total_load']:.1%}, nominal {budget['nominal_load']:.1%}"
        f" (limit {lim['max_load']:.0%})",
        f"worst cycle (slot {w['slot']} of {budget['hyper_period_cycles']}): SYNC {w['sync_bits']} + sensors "
        f"{w['sensors_bits']} + commands {w['commands_bits']} = {w['bus_bits']} bits",
        f"compute window: {budget['compute_window_us']:.1f} us (limit {lim['min_compute_window_us']:g} us); "
        f"{budget['compute_window_with_blocking_us']:.1f} us if a {budget['blocking_bits']}-bit sporadic frame blocks",
        "fits" if budget["fits"] else "DOES NOT FIT",
    ]
    return "\n".join(lines)
