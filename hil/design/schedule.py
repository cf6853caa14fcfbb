"""Gain-schedule design (chapter 7.5.1.1): a Ziegler-Nichols PI for every plant of a set, the
integral detuning, and the table over (position, load) in the controller's config format.

Ziegler-Nichols by the ultimate gain, computed exactly on the identified model: under a
proportional gain K the loop of G1 = k01 b0 / (s (s^2 + b1 s + b0)) has the characteristic
polynomial s^3 + b1 s^2 + b0 s + K k01 b0, which has a pair on the imaginary axis at
w_u = sqrt(b0) when K = K_u = b1 / k01 (Routh), so T_u = 2 pi / sqrt(b0). The PI rule is
Kp = 0.45 K_u, Ti = T_u / 1.2 (Ki = Kp / Ti). The thesis then multiplies every Ki by 0.2
(an overshoot near 25 %, Fig. 7.12); the file keeps the Ziegler-Nichols Ki and the 0.2 as
`ki_scale`, as Table 7.2 and the controller's config do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_py.config import SCHEDULE_LOADS, load_config
from hil.design.plants import MM, Plant, PlantSetError

ZN_KP_FRACTION = 0.45            # Kp = 0.45 Ku
ZN_TI_FRACTION = 1.0 / 1.2       # Ti = Tu / 1.2
KI_DETUNING = 0.2                # chapter 7.5.1.1: K'i = 0.2 Ki


@dataclass(frozen=True)
class Tuning:
    plant: Plant
    ku_v_m: float
    tu_s: float
    kp_v_m: float
    ki_v_m_s: float               # before the detuning


def ultimate(plant: Plant) -> tuple[float, float]:
    """(K_u V/m, T_u s) of the plant under proportional control."""
    return plant.b1 / plant.k01, 2.0 * math.pi / math.sqrt(plant.b0)


def ziegler_nichols(plant: Plant, kp_fraction: float = ZN_KP_FRACTION,
                    ti_fraction: float = ZN_TI_FRACTION) -> Tuning:
    ku, tu = ultimate(plant)
    kp = kp_fraction * ku
    return Tuning(plant, ku, tu, kp, kp / (ti_fraction * tu))


def tune(plants: list[Plant], kp_fraction: float = ZN_KP_FRACTION,
         ti_fraction: float = ZN_TI_FRACTION) -> list[Tuning]:
    return [ziegler_nichols(p, kp_fraction, ti_fraction) for p in plants]


def grid_of(tunings: list[Tuning]) -> tuple[np.ndarray, np.ndarray, dict[tuple[float, float], Tuning]]:
    """(positions m, loads kg, (position, load) -> tuning); a PlantSetError unless the set
    covers every position at each of three loads (the controller's table is that grid)."""
    cell = {(round(t.plant.position_m, 6), round(t.plant.load_kg, 6)): t for t in tunings}
    positions = np.array(sorted({p for p, _ in cell}))
    loads = np.array(sorted({m for _, m in cell}))
    missing = [(p, m) for p in positions for m in loads if (p, m) not in cell]
    if len(loads) != len(SCHEDULE_LOADS) or missing or len(positions) < 4:
        raise PlantSetError(f"plant set: the schedule needs >= 4 positions at each of {len(SCHEDULE_LOADS)} loads; "
                            f"got loads {list(loads)} and {len(missing)} missing (position, load) points")
    return positions, loads, cell


def schedule_toml(tunings: list[Tuning], source: str, ki_scale: float = KI_DETUNING) -> str:
    """The [adaptive] table in the controller's config format (thesis units: mm, V/mm)."""
    positions, loads, cell = grid_of(tunings)

    def row(values) -> str:
        return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"

    lines = [f"# hydrapod design schedule: Ziegler-Nichols PI per plant of {source}",
             "# (Kp = 0.45 Ku, Ti = Tu / 1.2 unless stated; chapter 7.5.1.1), Ki before the detuning",
             "# the controller applies (ki_scale). Load it with `--config` (controller) or",
             "# `hydrapod hil run ... --controller-config` (HIL).",
             "[adaptive]",
             f"ki_scale = {ki_scale:g}",
             f"table_position_mm = {row(positions / MM)}",
             f"table_load_kg = {row(loads)}"]
    for name, load in zip(SCHEDULE_LOADS, loads):
        tuned = [cell[(p, load)] for p in positions]
        lines.append(f"kp_{name}_v_mm = {row([t.kp_v_m * MM for t in tuned])}")
        lines.append(f"ki_{name}_v_mm_s = {row([t.ki_v_m_s * MM for t in tuned])}")
    return "\n".join(lines) + "\n"


def write_schedule(path: Path, text: str) -> None:
    """Write, then load it through the controller's own config validation (a file the
    controller would refuse is never left behind)."""
    path.write_text(text)
    try:
        load_config(path)
    except Exception:
        path.unlink()
        raise


def compare_with_table_7_2(tunings: list[Tuning], table: dict) -> list[dict]:
    """Per Table 7.2 cell present in the set: the thesis's Kp, Ki beside the designed ones."""
    cell = {(round(t.plant.position_m / MM, 3), t.plant.load_kg): t for t in tunings}
    out = []
    for row in table["rows"]:
        for j, load in enumerate((0.0, 3.0, 6.0)):
            t = cell.get((float(row[0]), load))
            if t is None:
                continue
            kp, ki = row[1 + 2 * j], row[2 + 2 * j]
            out.append({"position_mm": row[0], "load_kg": load, "kp_v_mm": t.kp_v_m * MM, "ki_v_mm_s": t.ki_v_m_s * MM,
                        "thesis_kp_v_mm": kp, "thesis_ki_v_mm_s": ki, "kp_ratio": t.kp_v_m * MM / kp,
                        "ki_ratio": t.ki_v_m_s * MM / ki, "ku_v_mm": t.ku_v_m * MM, "tu_ms": t.tu_s * 1e3,
                        "thesis_kp_over_ku": kp / (t.ku_v_m * MM),
                        "thesis_ki_tu_over_kp": ki * t.tu_s / kp})
    return out
