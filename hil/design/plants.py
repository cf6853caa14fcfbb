"""Plant sets for the design tools and the nominal plant (chapter 7.4.1).

A plant is the identified small-signal model of one set point (eq. 5.2, Table A.3):
G1(s) = Y/Xv = k01 b0 / (s (s^2 + b1 s + b0)), kept in SI (Y in m, Xv in V, k01 in
(m/s)/V); the thesis's mm appear only where a set is read or a table is printed.

Three sources: Table A.3 (the thesis's 33 plants), the emulator's own linearisation at the
same 33 set points (the plant the HIL runs against), and the `metrics.json` of a
`sha-identification` run (the plants identified from the bus, e.g. on the real rig).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from hil.design.calibration import LOADS_KG, linearise, table_a3
from hil.design.thesis import thesis_data
from hil.identification import fit_index
from physics.constants import MM
from plant_emulator.params import load_config as load_emulator_config
from program.errors import UserInputError

SOURCES = ("table-a3", "emulator")       # or a sha-identification metrics.json
# The identification registers of eq. 7.10-7.11, synthesised (the thesis's are not
# published): each plant's closed-loop response to a 10 mm reference step under the
# identification's proportional gain, 0.3 s at 500 Hz (chapter 5.4.1: +/-10 mm steps, K 0.25 V/mm).
REGISTER_GAIN_V_M = 0.25 / MM
REGISTER_STEP_M = 10.0 * MM
REGISTER_T_S = np.arange(0.0, 0.3, 0.002)


class PlantSetError(UserInputError):
    """A plant set that cannot be read: one line naming the file and what is wrong."""


@dataclass(frozen=True)
class Plant:
    position_m: float
    load_kg: float
    b0: float                 # 1/s^2
    b1: float                 # 1/s
    k01: float                # (m/s)/V: steady velocity per volt

    @property
    def label(self) -> str:
        return f"{self.position_m / MM:g} mm, {self.load_kg:g} kg"

    def num(self) -> np.ndarray:
        return np.array([self.k01 * self.b0])

    def den(self) -> np.ndarray:
        return np.array([1.0, self.b1, self.b0, 0.0])

    def response(self, w_rad_s: np.ndarray) -> np.ndarray:
        """G1(jw), m/V."""
        return signal.freqs(self.num(), self.den(), worN=w_rad_s)[1]


def chapter7() -> dict:
    """The thesis's chapter 7 numbers (data/chapter7.toml, the project's copy)."""
    return thesis_data("chapter7")


def table_a3_plants() -> list[Plant]:
    rows = table_a3()
    return [Plant(row[0] * MM, load, row[1 + 3 * j], row[2 + 3 * j], row[3 + 3 * j] * MM)
            for j, load in enumerate(LOADS_KG) for row in rows]


def emulator_plants(config: str | None = None) -> list[Plant]:
    """The emulator's linearisation (hil.design.calibration) at Table A.3's set points."""
    cfg = load_emulator_config(config)
    plants = []
    for load in LOADS_KG:
        for position_mm in table_a3()[:, 0]:
            op = linearise(cfg, float(position_mm), load)
            plants.append(Plant(position_mm * MM, load, op.b0, op.b1, op.k01 * MM))
    return plants


def identified_plants(path: str | Path) -> list[Plant]:
    """The plants a `sha-identification` run identified (its metrics.json)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
        points = doc["metrics"]["points"]
    except FileNotFoundError:
        raise PlantSetError(f"plant set {path}: no such file") from None
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise PlantSetError(f"plant set {path}: not a sha-identification metrics.json ({error})") from None
    plants = [Plant(p["set_point_mm"] * MM, float(p["load_kg"] or 0.0), p["identified"]["b0"],
                    p["identified"]["b1"], p["identified"]["k01"] * MM)
              for p in points if p.get("identified")]
    if len(plants) < 2:
        raise PlantSetError(f"plant set {path}: {len(plants)} identified plant(s); the design needs >= 2")
    return plants


def plant_set(source: str) -> list[Plant]:
    if source == "table-a3":
        return table_a3_plants()
    if source == "emulator":
        return emulator_plants()
    return identified_plants(source)


def _discrete(plant: Plant) -> tuple[np.ndarray, np.ndarray]:
    """G1 under a zero-order hold at the register's sampling (a 500 Hz controller holds the
    valve input over each period): (b, a) of the difference equation."""
    dt = float(REGISTER_T_S[1] - REGISTER_T_S[0])
    b, a, _ = signal.cont2discrete((plant.num(), plant.den()), dt, method="zoh")
    return b.ravel(), a


def register(plant: Plant) -> tuple[np.ndarray, np.ndarray]:
    """One synthesised identification register (valve input V, position m) of `plant`: the
    sampled loop u[k] = K (r - y[k]) after a reference step, the plant held between samples."""
    b, a = _discrete(plant)
    n = len(REGISTER_T_S)
    u, y = np.zeros(n), np.zeros(n)
    for k in range(n):
        # y[k] from the past inputs and outputs (b[0] = 0: no direct feedthrough under a hold)
        y[k] = (np.dot(b[1:k + 1], u[k - 1::-1][:len(b) - 1]) - np.dot(a[1:k + 1], y[k - 1::-1][:len(a) - 1])
                if k else 0.0)
        u[k] = REGISTER_GAIN_V_M * (REGISTER_STEP_M - y[k])
    return u, y


def fit_scores(plants: list[Plant], registers: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """F[j, i] of eq. 7.11: plant j simulated with register i's input against its output."""
    scores = np.empty((len(plants), len(registers)))
    for j, plant in enumerate(plants):
        b, a = _discrete(plant)
        for i, (u, y) in enumerate(registers):
            scores[j, i] = fit_index(y, signal.lfilter(b, a, u))
    return scores


def select_nominal(plants: list[Plant]) -> tuple[int, np.ndarray]:
    """Eq. 7.10: the plant whose simulations fit every register best (max of the sum of F_i)."""
    scores = fit_scores(plants, [register(p) for p in plants])
    return int(np.argmax(scores.sum(axis=1))), scores
