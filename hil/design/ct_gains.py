"""The computed-torque gains, derived from the emulated rigs' models (not hand-tuned).

The hexapod's, two requirements, each judged on a model of item 1 (`hydrapod design modes`):

- robust stability: every mode of the closed loop (`closed_loop.hexapod_closed_loop`: the
  plant linearised at a pose under the controller's own code) damped at least `min_damping`
  at every point of the operating set: the movements' corner poses x payload 0 and 6 kg x
  supply 20 and 40 bar (the spread a rig sees; the nominal point is damped far more);
- tracking: the thesis's two movements at its timing, in process on the emulator's equations
  (`simulate`), scored as the issue's bounds normalise them: the worst of the largest error
  / 10 mm and the IAE / (2 x the thesis's model-based IAE) over both movements and every
  axis (<= 1: both bounds met).

The test bench's one leg, on its own experiments in process: sha-step's steps (overshoot
< 14 %, settling <= 1 s: the thesis's claim for its adaptive controller) as the constraint,
the largest error of sha-tracking's sines at w 0.5 and 1 rad/s with 0, 3 and 6 kg and at
0.1 rad/s with 3 kg / 1 mm (its claim at low w) as the score.

The search: a seeded random sample of the gain ranges; the cheap requirement first, the
rest only for the candidates it passes; then Nelder-Mead from the best on the same
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
    "force_bandwidth_hz": (3.0, 30.0),    # while moving; at rest [computed_torque] force_bandwidth_rest_hz
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
# the searches' defaults (samples, Nelder-Mead evaluations, seed): what made the packaged gains
HEXAPOD_SEARCH = (64, 40, 1)
TESTBENCH_SEARCH = (256, 60, 3)


@dataclass
class Candidate:
    gains: dict
    damping: float                   # the worst closed-loop damping ratio over the operating set
    worst_point: str
    score: float = math.inf          # the tracking score (<= 1: the bounds met); inf: not simulated
    movements: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"gains": {k: round(v, 4) for k, v in self.gains.items() if k in GAIN_RANGES or k in TESTBENCH_RANGES},
                "min_damping": round(self.damping, 4),
                "worst_point": self.worst_point, "score": round(self.score, 4), "movements": self.movements}


def operating_set(cfg: EmulatorConfig) -> list[tuple[str, object]]:
    """(label, ModalModel) of every point of the operating set."""
    from hil.design.modes import modal_model
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
    from hil.design.closed_loop import hexapod_closed_loop
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
    from hil.design.simulate import run_movement, thesis_motions
    from hil.experiments import IAE_FACTOR_MAX, MAX_ERROR_MM, MOVEMENT_OVERRIDES, THESIS_MOVEMENTS
    overrides = {section: dict(values) for section, values in MOVEMENT_OVERRIDES.items()}
    overrides["computed_torque"] = gains
    ctl_cfg = load_config(overrides=overrides)
    motions = thesis_motions()
    score, figures = 0.0, {}
    for name in ("circle", "diagonal"):
        run = run_movement(ctl_cfg, cfg, motions[name])
        thesis = THESIS_MOVEMENTS[name]["iae_model_based"]
        iae, largest = run.iae_m_s, run.max_error_m * 1e3
        ratios = [largest[i] / MAX_ERROR_MM for i in range(3)]
        ratios += [iae[i] / (IAE_FACTOR_MAX * thesis[a]) for i, a in enumerate("xyz")]
        score = max(score, max(ratios) if run.completed else INFEASIBLE)
        figures[f"pm-{name}"] = {"fault": run.fault, "iae_m_s": [round(float(v), 5) for v in iae],
                                  "max_error_mm": [round(float(v), 2) for v in largest]}
    return score, figures


def _evaluate(args) -> Candidate:
    cfg, models, gains, min_damping = args
    zeta, where, _ = worst_damping(cfg, models, gains)
    candidate = Candidate(gains, zeta, where)
    if zeta >= min_damping:
        candidate.score, candidate.movements = tracking(cfg, gains)
    return candidate


def _gains_of(unit: np.ndarray, ranges: dict) -> dict:
    """Gains from a point of the unit box (clipped into it)."""
    unit = np.clip(unit, 0.0, 1.0)
    return {name: float(low + u * (high - low)) for u, (name, (low, high)) in zip(unit, ranges.items())}


def _penalised(candidate: Candidate, min_damping: float) -> float:
    if candidate.damping < min_damping:
        return 2 * INFEASIBLE + 100.0 * (min_damping - candidate.damping)
    return candidate.score


def _search(evaluate, argument_of, ranges: dict, samples: int, refine: int, seed: int, workers: int, progress,
            penalised) -> tuple[Candidate, list]:
    """A seeded random sample of `ranges`, then Nelder-Mead from the best on `penalised`."""
    from scipy.optimize import minimize
    rng = np.random.default_rng(seed)
    units = [rng.random(len(ranges)) for _ in range(samples)]
    tried: list[Candidate] = []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for candidate in pool.map(evaluate, [argument_of(_gains_of(u, ranges)) for u in units]):
            tried.append(candidate)
            if progress:
                progress(len(tried), candidate)
    if refine > 0 and tried:
        start = units[int(np.argmin([penalised(c) for c in tried]))]

        def cost(unit):
            candidate = evaluate(argument_of(_gains_of(unit, ranges)))
            tried.append(candidate)
            if progress:
                progress(len(tried), candidate)
            return penalised(candidate)
        minimize(cost, np.clip(start, 0.0, 1.0), method="Nelder-Mead",
                 options={"maxfev": refine, "xatol": 1e-3, "fatol": 1e-3})
    return min(tried, key=penalised), tried


def design_gains(cfg: EmulatorConfig, samples: int = HEXAPOD_SEARCH[0], refine: int = HEXAPOD_SEARCH[1],
                 seed: int = HEXAPOD_SEARCH[2],
                 min_damping: float = MIN_DAMPING, workers: int = 2, progress=None, models=None,
                 rate_floor: float | None = None) -> tuple[Candidate, list]:
    """The hexapod's: the best candidate and every one evaluated (see the module docstring);
    `models`: the operating set (default `operating_set`), `rate_floor` the force loop's (N/s
    per unit spool; default the packaged one)."""
    models = operating_set(cfg) if models is None else models
    fixed = {} if rate_floor is None else {"force_rate_floor_n_s_pct": rate_floor / 100.0}
    return _search(_evaluate, lambda gains: (cfg, models, gains | fixed, min_damping), GAIN_RANGES, samples, refine,
                   seed, workers, progress, lambda c: _penalised(c, min_damping))


# -- the test bench's one leg ---------------------------------------------------------------------

TESTBENCH_RANGES = {
    "testbench_bandwidth_hz": (1.0, 6.0),
    "testbench_damping": (0.4, 1.2),
    "testbench_force_bandwidth_hz": (3.0, 40.0),
    "testbench_velocity_gain_per_s": (10.0, 120.0),
    "testbench_velocity_filter_hz": (10.0, 150.0),
    "testbench_integral_fraction": (0.1, 1.0),
}
# (kg, rad/s): w 0.5 and 1 at every load, and the slowest, 0.1, where the seals' stick-slip at
# the reversals is largest (3 kg: 1.00 mm through the bus with gains that gave 0.93 at 0.5-1)
BENCH_SINES = ((0.0, 0.5), (3.0, 0.5), (6.0, 0.5), (0.0, 1.0), (3.0, 1.0), (6.0, 1.0), (3.0, 0.1))
BENCH_STEPS = tuple((load, position) for load in (0.0, 3.0, 6.0) for position in (0.05, 0.15, 0.25))  # sha-step's
MAX_ERROR_M = 1e-3                   # the thesis's claim at low w (7.6.2)
# its claim for the adaptive controller (7.6.1): overshoot < 14 %, settling <= 1 s. The
# overshoot is read in encoder counts, 1.25 % of the 10 mm step: the design keeps one count
# below the claim (in process a step came out 13.75 % where the bus's run gave 15.0 %)
OVERSHOOT_MAX_PCT, SETTLING_MAX_S = 14.0 - 1.25, 1.0


def _evaluate_bench(args) -> Candidate:
    """The bench's score: the largest sine error / 1 mm over BENCH_SINES; infeasible (the
    damping field -1) when a step overshoots 14 % or settles later than 1 s."""
    from firmware_py.config import load_config
    from hil.design.simulate import bench_sine, bench_step
    from hil.experiments import TRACKING_OVERRIDES
    cfg, gains = args
    plain = load_config(overrides={"computed_torque": gains})
    tracking_cfg = load_config(overrides={**{k: dict(v) for k, v in TRACKING_OVERRIDES.items()},
                                          "computed_torque": gains})
    figures, feasible = {}, True
    for load, position in BENCH_STEPS:
        step = bench_step(plain, cfg, load, position)
        feasible &= "fault" not in step and step["overshoot_pct"] < OVERSHOOT_MAX_PCT and (
            step["settling_s"] <= SETTLING_MAX_S)
        figures[f"step {load:g} kg at {position * 1e3:g} mm"] = {k: round(v, 3) if isinstance(v, float) else v
                                                                for k, v in step.items()}
    score = 0.0
    if feasible:
        for load, w in BENCH_SINES:
            error, fault = bench_sine(tracking_cfg, cfg, load, w)
            score = max(score, error / MAX_ERROR_M if fault == "NONE" else INFEASIBLE)
            figures[f"sine {load:g} kg at {w:g} rad/s"] = {"max_error_mm": round(error * 1e3, 3), "fault": fault}
    return Candidate(gains, 1.0 if feasible else -1.0, "", score if feasible else math.inf, figures)


def design_testbench_gains(cfg: EmulatorConfig, samples: int = TESTBENCH_SEARCH[0], refine: int = TESTBENCH_SEARCH[1],
                           seed: int = TESTBENCH_SEARCH[2], workers: int = 2, progress=None
                           ) -> tuple[Candidate, list]:
    """The test bench's gains: sha-step's claim (overshoot < 14 % less one count, settling
    <= 1 s, at its 50, 150 and 250 mm with 0, 3 and 6 kg) as the constraint, the largest error
    of sha-tracking's sines (BENCH_SINES) as the score (in process)."""
    return _search(_evaluate_bench, lambda gains: (cfg, gains), TESTBENCH_RANGES, samples, refine, seed, workers,
                   progress, lambda c: _penalised(c, 0.0))
