"""The computed-torque gains, derived from the emulated hexapod's models (not hand-tuned).

Two requirements, each judged on a model of item 1 (`hydrapod design modes`):

- robust stability: every mode of the closed loop (`closed_loop.hexapod_closed_loop`: the
  plant linearised at a pose under the controller's own code) damped at least `min_damping`
  at every point of the operating set: the movements' corner poses x payload 0 and 6 kg x
  supply 20 and 40 bar (the spread a rig sees; the nominal point is damped far more);
- tracking: the thesis's two movements at its timing, in process on the emulator's equations
  (`simulate`), scored as the issue's bounds normalise them: the worst of the largest error
  / 10 mm and the IAE / (2 x the thesis's model-based IAE) over both movements and every
  axis (<= 1: both bounds met).

The search: a seeded random sample of the gain ranges; the stability check first (cheap), the
movements only for the candidates it passes; then Nelder-Mead from the best on the same
penalised score. Deterministic for a seed.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from physics.constants import BAR
from plant_emulator.params import EmulatorConfig

GAIN_RANGES = {                      # the search's box, [computed_torque] keys (thesis units)
    "bandwidth_hz": (1.5, 4.5),
    "damping": (0.4, 1.2),
    "force_bandwidth_hz": (3.0, 30.0),
    "velocity_gain_per_s": (5.0, 40.0),
    "velocity_filter_hz": (10.0, 60.0),
    "integral_fraction": (0.1, 0.6),
}
# the operating set: home, the cube's centre, its lowest and highest vertices, the circle's
# start and its point at 30 deg (the movements' extremes of leg force and stiffness)
DESIGN_POSES_M = {"home": (0.0, 0.0, 0.5835), "cube centre": (0.0, 0.0, 0.66), "cube low": (-0.1, -0.1, 0.56),
                  "cube high": (0.1, 0.1, 0.76), "circle start": (0.2, 0.0, 0.631),
                  "circle 30 deg": (0.1732, 0.1, 0.631)}
DESIGN_PAYLOADS_KG = (0.0, 6.0)
DESIGN_SUPPLIES_BAR = (20.0, 40.0)
MIN_DAMPING = 0.15
INFEASIBLE = 100.0                   # a candidate's score when a movement faults


@dataclass
class Candidate:
    gains: dict
    damping: float                   # the worst closed-loop damping ratio over the operating set
    worst_point: str
    score: float = math.inf          # the tracking score (<= 1: the bounds met); inf: not simulated
    movements: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"gains": {k: round(v, 4) for k, v in self.gains.items() if k in GAIN_RANGES},
                "min_damping": round(self.damping, 4),
                "worst_point": self.worst_point, "score": round(self.score, 4), "movements": self.movements}


def operating_set(cfg: EmulatorConfig) -> list[tuple[str, object]]:
    """(label, ModalModel) of every point of the operating set."""
    from .modes import modal_model
    out = []
    for name, pose in DESIGN_POSES_M.items():
        for payload in DESIGN_PAYLOADS_KG:
            for supply in DESIGN_SUPPLIES_BAR:
                model = modal_model(cfg, np.array(pose), payload_kg=payload, supply_pa=supply * BAR)
                out.append((f"{name}, {payload:g} kg, {supply:g} bar", model))
    return out


def worst_damping(cfg: EmulatorConfig, models, gains: dict) -> tuple[float, str, float]:
    """(the smallest damping ratio of the closed loop's modes over `models`, where, its
    frequency Hz) for the controller with `gains`."""
    from .closed_loop import hexapod_closed_loop
    worst = (math.inf, "", 0.0)
    for label, model in models:
        loop = hexapod_closed_loop(cfg, model.position_m, payload_kg=model.payload_kg, supply_pa=model.supply_pa,
                                   overrides={"computed_torque": gains}, model=model)
        s = np.log(np.linalg.eigvals(loop.phi).astype(complex)) / loop.period_s
        magnitude = np.abs(s)
        zeta = np.where(magnitude > 1e-9, -s.real / np.maximum(magnitude, 1e-12), 1.0)
        k = int(np.argmin(zeta))
        if zeta[k] < worst[0]:
            worst = (float(zeta[k]), label, float(magnitude[k] / (2 * math.pi)))
    return worst


def tracking(cfg: EmulatorConfig, gains: dict) -> tuple[float, dict]:
    """The tracking score of `gains` and each movement's figures (in process)."""
    from firmware_py.config import load_config

    from ..scenarios.pm import IAE_FACTOR_MAX, MAX_ERROR_MM, PlatformMovement, PmCircle, PmDiagonal
    from .simulate import run_movement, thesis_motions
    overrides = {section: dict(values) for section, values in PlatformMovement.controller_overrides.items()}
    overrides["computed_torque"] = gains
    ctl_cfg = load_config(overrides=overrides)
    motions = thesis_motions()
    score, figures = 0.0, {}
    for scenario in (PmCircle, PmDiagonal):
        run = run_movement(ctl_cfg, cfg, motions[scenario.motion_name])
        thesis = scenario.thesis["iae_model_based"]
        iae, largest = run.iae_m_s, run.max_error_m * 1e3
        ratios = [largest[i] / MAX_ERROR_MM for i in range(3)]
        ratios += [iae[i] / (IAE_FACTOR_MAX * thesis[a]) for i, a in enumerate("xyz")]
        score = max(score, max(ratios) if run.completed else INFEASIBLE)
        figures[scenario.name] = {"fault": run.fault, "iae_m_s": [round(float(v), 5) for v in iae],
                                  "max_error_mm": [round(float(v), 2) for v in largest]}
    return score, figures


def _evaluate(args) -> Candidate:
    cfg, models, gains, min_damping = args
    zeta, where, _ = worst_damping(cfg, models, gains)
    candidate = Candidate(gains, zeta, where)
    if zeta >= min_damping:
        candidate.score, candidate.movements = tracking(cfg, gains)
    return candidate


def _gains_of(unit: np.ndarray) -> dict:
    """Gains from a point of the unit box (clipped into it)."""
    unit = np.clip(unit, 0.0, 1.0)
    return {name: float(low + u * (high - low)) for u, (name, (low, high)) in zip(unit, GAIN_RANGES.items())}


def _penalised(candidate: Candidate, min_damping: float) -> float:
    if candidate.damping < min_damping:
        return 2 * INFEASIBLE + 100.0 * (min_damping - candidate.damping)
    return candidate.score


def design_gains(cfg: EmulatorConfig, samples: int = 64, refine: int = 40, seed: int = 1,
                 min_damping: float = MIN_DAMPING, workers: int = 2, progress=None, models=None,
                 rate_floor: float | None = None) -> tuple[Candidate, list]:
    """The best candidate and every one evaluated (see the module docstring); `models`: the
    operating set (default `operating_set`), `rate_floor` the force loop's (N/s per unit
    spool; default the packaged one)."""
    from scipy.optimize import minimize
    models = operating_set(cfg) if models is None else models
    fixed = {} if rate_floor is None else {"force_rate_floor_n_s_pct": rate_floor / 100.0}
    rng = np.random.default_rng(seed)
    units = [rng.random(len(GAIN_RANGES)) for _ in range(samples)]
    tried: list[Candidate] = []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for candidate in pool.map(_evaluate, [(cfg, models, _gains_of(u) | fixed, min_damping) for u in units]):
            tried.append(candidate)
            if progress:
                progress(len(tried), candidate)
    best_index = int(np.argmin([_penalised(c, min_damping) for c in tried]))
    if refine > 0:
        def cost(unit):
            candidate = _evaluate((cfg, models, _gains_of(unit) | fixed, min_damping))
            tried.append(candidate)
            if progress:
                progress(len(tried), candidate)
            return _penalised(candidate, min_damping)
        minimize(cost, np.clip(units[best_index], 0.0, 1.0), method="Nelder-Mead",
                 options={"maxfev": refine, "initial_simplex": None, "xatol": 1e-3, "fatol": 1e-3})
    best = min(tried, key=lambda c: _penalised(c, min_damping))
    return best, tried
