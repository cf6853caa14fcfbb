"""The controller's chapter 7.5 estimates as a log carries them (CTRL_LOAD): the RLS load mass
against the load the emulator carried (Fig. 7.14), the indirect load pressure against the
one the chamber transducers give (Fig. 7.15)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.logdata import LogData
from protocol.enums import EmuCommand

SETTLED_FRACTION = 0.10          # an estimate within this share of the true mass has settled


@dataclass
class LoadEstimates:
    """One leg's CTRL_LOAD samples on the log's cycles."""
    cycle: np.ndarray
    mass_kg: np.ndarray
    load_pressure_pa: np.ndarray
    friction_n: np.ndarray


def load_estimates(log: LogData, leg: int = 1) -> LoadEstimates:
    series = log.get("CTRL_LOAD")
    mine = series["LEG"] == leg if len(series) else np.zeros(0, dtype=bool)
    return LoadEstimates(series.cycle[mine], series["MASS"][mine], series["LOAD_PRESSURE"][mine],
                         series["FRICTION"][mine])


def load_changes(log: LogData) -> list[tuple[int, float]]:
    """(cycle, load kg) of every EMU_CTRL SET_LOAD."""
    return [(e.cycle, float(e.values["LOAD_MASS"])) for e in log.events_named("EMU_CTRL")
            if int(e.values["COMMAND"]) == EmuCommand.SET_LOAD]


def settling(estimates: LoadEstimates, start: int, end: int, true_kg: float, period_s: float,
             memory_s: float) -> dict:
    """Over cycles [start, end) with `true_kg` carried: when the estimate entered, for good,
    SETTLED_FRACTION of it (None: it never did), its error at the end, and what an RLS whose
    forgetting remembers `memory_s` (T / (1 - lambda)) does from where the estimate started,
    its error decaying as exp(-t / memory_s): the time it takes to settle,
    memory_s ln(|m_0 - m| / (SETTLED_FRACTION m)), and its error at the last sample."""
    inside = (estimates.cycle >= start) & (estimates.cycle < end)
    cycles, mass = estimates.cycle[inside], estimates.mass_kg[inside]
    if not len(mass):
        return {"true_kg": true_kg, "settled_s": None, "final_kg": None, "final_error_pct": None,
                "predicted_s": None}
    start_error = abs(float(mass[0]) - true_kg)
    gap = start_error / (SETTLED_FRACTION * true_kg)
    predicted = round(memory_s * float(np.log(gap)), 3) if gap > 1.0 else 0.0
    span_s = float((cycles[-1] - start) * period_s)
    within = np.abs(mass - true_kg) <= SETTLED_FRACTION * true_kg
    outside = np.flatnonzero(~within)
    first = 0 if not len(outside) else outside[-1] + 1
    settled = None if first >= len(mass) else round(float((cycles[first] - start) * period_s), 3)
    return {"true_kg": round(true_kg, 3), "settled_s": settled, "predicted_s": predicted,
            "span_s": round(span_s, 3), "final_kg": round(float(mass[-1]), 3),
            "final_error_kg": round(abs(float(mass[-1]) - true_kg), 3),
            "predicted_final_error_kg": round(start_error * float(np.exp(-span_s / memory_s)), 3),
            "final_error_pct": round(float((mass[-1] - true_kg) / true_kg * 100.0), 1)}


def direct_load_pressure(log: LogData, area_ratio: float, leg: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(cycles, P_A - alpha P_B) of the leg's chamber transducers (LEG_PRESSURE): the load
    pressure the piston's force over its area gives, Fig. 7.15's direct measurement."""
    series = log.get(f"LEG_PRESSURE_{leg}")
    return series.cycle, series["PA"] - area_ratio * series["PB"]


def follows_forgetting(segment: dict, factor: float) -> bool:
    """The estimate settled within `factor` x the time its forgetting needs; where that time is
    longer than the segment, its error at the end within `factor` x the forgetting's there."""
    if segment["predicted_s"] is None:
        return False
    if segment["predicted_s"] <= segment["span_s"]:
        return segment["settled_s"] is not None and segment["settled_s"] <= factor * segment["predicted_s"]
    return segment["final_error_kg"] <= factor * segment["predicted_final_error_kg"]
