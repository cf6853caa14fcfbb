"""A campaign spec (TOML): one scenario run over a grid and/or a Monte-Carlo draw of its
parameters. Everything is checked before anything runs: an unknown key, a bad range or an
unknown scenario is one line naming the file and the key (exit 2).

    [campaign]
    scenario = "sha-step"        # any of `hydrapod hil list` with lockstep pacing
    short = true
    timeout_s = 600              # a run still going after this is stopped and recorded as hung
    metrics = ["overshoot_pct_max", "settling_s_max"]   # reported and plotted (default: all)
    compare = "design-robustness"  # sha-step: the PI's worst beside the linear prediction

    [grid]                       # every combination of these lists
    controller = ["pi", "adaptive"]
    fault = ["", "SEAL_LEAK:1:10"]   # emulator faults for the whole run (as `hil run --inject`)
    load_kg = [0.0, 6.0]         # scenarios that run at several loads
    position_mm = [50.0]         # sha-step's working positions
    payload_kg = [0.0]           # the hexapod's payload, declared to the controller too
    time_scale = [1.0, "auto"]    # pm-*: the thesis's timing, this many times slower; "auto", "fit": planned
    supply_bar = [25.0]          # the power unit's, and the controller's model's unless set
    noise = [1.0]                # the sensors' noise, x the emulator's
    seed = [1]                   # the emulator's noise seed
    [grid.scale]                 # plant parameters, x their emulator value
    leakage = [0.8, 1.2]
    [grid.controller_config]     # any controller config key, "section.key" = values
    "pi.kp_v_mm" = [0.06, 0.085]
    [grid.emulator_config]       # any emulator config key, the same way
    "valve.spool_time_constant_ms" = [1.5, 3.0]

    [montecarlo]                 # draws for every grid point
    draws = 4
    seed = 1
    [montecarlo.scale]           # uniform in [1 - x, 1 + x]
    stiffness = 0.2

    [controller_config]          # sections over the controller's config, every run
    [emulator_config]            # sections over the emulator's config, every run
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from firmware_py.config import load_config as controller_config_load
from hil.experiments import PLANNED_TIME_SCALES
from hil.injection import parse_faults
from physics.actuator import PAYLOAD
from physics.constants import BAR
from physics.hydraulics import SUPPLY_PRESSURE
from plant_emulator.params import Testbench as EmulatorTestbench
from plant_emulator.params import load_raw as emulator_raw_load
from program.errors import UserInputError
from program.sections import read_toml

# plant parameter groups: the emulator's (section, key) scaled together
SCALES = {
    "stiffness": (("chambers", "oil_bulk_modulus_bar"), ("chambers", "hose_bulk_modulus_bar")),
    "leakage": (("chambers", "cross_leakage_l_min_per_bar"), ("chambers", "seal_leakage_l_min_per_bar")),
    "flow_gain": (("valve", "edge_flow_l_min"),),
    "dead_volume": (("chambers", "dead_volume_a_cm3"), ("chambers", "dead_volume_b_cm3")),
    "friction": tuple(("friction", k) for k in ("alpha0_pos_n", "alpha1_pos_n", "sigma2_pos_ns_mm", "alpha0_neg_n",
                                                "alpha1_neg_n", "sigma2_neg_ns_mm")),
}
NOISES = (("sensors", "load_cell_noise_n"), ("sensors", "pressure_noise_bar"), ("sensors", "imu_angle_noise_rad"),
          ("sensors", "imu_rate_noise_rad_s"))
# grid keys: kind and range
GRID_KEYS = {"controller": str, "fault": "fault", "load_kg": EmulatorTestbench.keys()["load_kg"].range,
             "position_mm": (0.0, 304.0), "payload_kg": PAYLOAD.range, "supply_bar": SUPPLY_PRESSURE.range,
             "noise": (0.0, 100.0), "seed": (0, 2**31 - 1), "time_scale": (0.5, 20.0)}
# grid keys that are the controller's to know as well (an operator sets them on the rig)
TOLD = {"supply_bar": ("hydraulic_model", "supply_pressure_bar"), "payload_kg": ("hexapod", "payload_kg")}
SCALE_RANGE = (0.1, 10.0)            # a grid scale factor
SPREAD_RANGE = (0.0, 0.9)            # a Monte-Carlo half-width
MAX_RUNS = 100_000
COMPARISONS = {"design-robustness": "sha-step"}      # a prediction the report sets beside the runs
SECTIONS = ("campaign", "grid", "montecarlo", "controller_config", "emulator_config")


class SpecError(UserInputError):
    pass


@dataclass(frozen=True)
class Run:
    """One HIL run of the campaign: its parameters (grid values and drawn scales)."""
    params: dict

    @property
    def run_id(self) -> str:
        """The parameter hash: the same parameters are the same run (`--resume`)."""
        text = json.dumps(self.params, sort_keys=True, default=float)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass
class Campaign:
    name: str
    scenario: str
    short: bool
    timeout_s: float
    metrics: tuple[str, ...]
    compare: str | None
    grid: dict
    draws: int
    draw_seed: int
    spreads: dict
    controller_config: dict = field(default_factory=dict)
    emulator_config: dict = field(default_factory=dict)
    source: str = ""

    def runs(self) -> list[Run]:
        """Every grid point x every draw, in a fixed order (the draws from `draw_seed`)."""
        keys = list(self.grid)
        points = [dict(zip(keys, values)) for values in itertools.product(*(self.grid[k] for k in keys))]
        rng = np.random.default_rng(self.draw_seed)
        runs = []
        for point in points:
            for draw in range(max(self.draws, 1)):
                params = dict(point)
                if self.draws:
                    params["draw"] = draw
                    for name, spread in self.spreads.items():
                        factor = float(rng.uniform(1.0 - spread, 1.0 + spread))
                        params[f"scale.{name}"] = round(params.get(f"scale.{name}", 1.0) * factor, 6)
                runs.append(Run(params))
        return runs

    def controller_sections(self, params: dict) -> dict:
        """The run's controller config sections: the campaign's, then its grid's keys; a
        `supply_bar` or `payload_kg` is the controller's too unless one of those sets it (as a
        rig's operator sets `supply_pressure_bar` to the power unit's and declares the payload).
        So are how well the plant is known, for the fault monitors' thresholds: a flow gain,
        leakage or stiffness drawn wider than its `[residuals]` spread, and the sensors' noise
        x `noise`."""
        sections = _with_keys(self.controller_config, params, "controller_config.")
        for name, (section, key) in TOLD.items():
            if name in params and key not in sections.get(section, {}):
                sections.setdefault(section, {})[key] = float(params[name])
        known = controller_config_load()
        told = {}
        for name, key, spread in (("flow_gain", "flow_spread_pct", known.residuals.flow_spread),
                                  ("leakage", "leakage_spread_pct", known.residuals.leakage_spread),
                                  ("stiffness", "stiffness_spread_pct", known.residuals.stiffness_spread)):
            if self.spreads.get(name, 0.0) > spread:
                told[key] = 100.0 * self.spreads[name]
        if "noise" in params:
            told["pressure_noise_bar"] = known.residuals.pressure_noise_pa / BAR * float(params["noise"])
            told["load_cell_noise_n"] = known.residuals.load_cell_noise_n * float(params["noise"])
        residuals = sections.setdefault("residuals", {}) if told else {}
        for key, value in told.items():
            residuals.setdefault(key, round(value, 9))
        return sections

    def emulator_sections(self, params: dict, nominal: dict) -> dict:
        """The run's emulator config sections: the campaign's and its grid's keys, then supply,
        payload, noise, seed and the scaled plant parameters (`nominal`: the emulator's values,
        thesis units)."""
        sections = _with_keys(self.emulator_config, params, "emulator_config.")

        def put(section: str, key: str, value) -> None:
            sections.setdefault(section, {})[key] = value

        def base(section: str, key: str) -> float:
            return float(sections.get(section, {}).get(key, nominal[section][key]))

        if "supply_bar" in params:
            put("actuator", "supply_pressure_bar", float(params["supply_bar"]))
        if "payload_kg" in params:
            put("hexapod", "payload_kg", float(params["payload_kg"]))
        if "seed" in params:
            put("sensors", "seed", int(params["seed"]))
        if "noise" in params:
            for section, key in NOISES:
                put(section, key, base(section, key) * float(params["noise"]))
        for name, pairs in SCALES.items():
            factor = params.get(f"scale.{name}")
            if factor is not None:
                for section, key in pairs:
                    put(section, key, base(section, key) * float(factor))
        return sections


def _with_keys(sections: dict, params: dict, prefix: str) -> dict:
    """`sections` with the params named `<prefix><section>.<key>` set."""
    out = {section: dict(values) for section, values in sections.items()}
    for name, value in params.items():
        if name.startswith(prefix):
            section, key = name.removeprefix(prefix).split(".", 1)
            out.setdefault(section, {})[key] = value
    return out


def _fail(source: str, where: str, why: str) -> SpecError:
    return SpecError(f"campaign {source}: {where}: {why}")


def _number(source: str, where: str, value, lo: float, hi: float, integer: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        raise _fail(source, where, f"{value!r} is not {'an integer' if integer else 'a number'}")
    if not (math.isfinite(value) and lo <= value <= hi):
        raise _fail(source, where, f"{value!r} is outside {lo:g}..{hi:g}")
    return value


def _only(source: str, where: str, table, allowed) -> dict:
    if not isinstance(table, dict):
        raise _fail(source, where, "is not a table")
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise _fail(source, f"{where}.{unknown[0]}" if where else unknown[0],
                    f"unknown key (known: {', '.join(allowed)})")
    return table


def _list(source: str, where: str, value) -> list:
    if not isinstance(value, list) or not value:
        raise _fail(source, where, "is not a non-empty list")
    return value


def _config_grid(source: str, table: str, values) -> dict:
    """`[grid.controller_config]` / `[grid.emulator_config]`: "section.key" = [values], each
    value checked by that config's own validation."""
    if not isinstance(values, dict):
        raise _fail(source, f"grid.{table}", "is not a table of \"section.key\" = [values]")
    load = CONFIGS[table]
    grid = {}
    flat = {}
    for name, options in values.items():          # "section.key" = [...], or section.key = [...] (nested)
        if isinstance(options, dict):
            flat.update({f"{name}.{key}": v for key, v in options.items()})
        else:
            flat[name] = options
    for name, options in flat.items():
        where = f"grid.{table}.{name}"
        if not isinstance(name, str) or name.count(".") != 1:
            raise _fail(source, where, "not \"section.key\"")
        section, key = name.split(".")
        for value in _list(source, where, options):
            try:
                load(None, {section: {key: value}})
            except UserInputError as error:
                raise _fail(source, where, str(error)) from None
        grid[f"{table}.{name}"] = list(options)
    return grid


# each config's own validation: defaults, a file (None), then the sections given
CONFIGS = {"controller_config": controller_config_load, "emulator_config": emulator_raw_load}


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a spec; raises SpecError (one line) on any problem."""
    path = Path(path)
    source = str(path)
    raw = read_toml(path, SpecError)
    _only(source, "", raw, SECTIONS)
    head = _only(source, "campaign", raw.get("campaign", {}),
                 ("name", "scenario", "short", "timeout_s", "metrics", "compare"))
    scenario_name = head.get("scenario")
    if not isinstance(scenario_name, str):
        raise _fail(source, "campaign.scenario", "missing (a name from `hydrapod hil list`)")
    from hil.scenarios import SCENARIOS
    scenario = SCENARIOS.get(scenario_name)
    if scenario is None:
        raise _fail(source, "campaign.scenario", f"unknown scenario {scenario_name!r} (known: {', '.join(SCENARIOS)})")
    if "lockstep" not in scenario.pacings:
        raise _fail(source, "campaign.scenario", f"{scenario_name} runs in realtime only; campaigns run lockstep")
    short = head.get("short", True)
    if not isinstance(short, bool):
        raise _fail(source, "campaign.short", f"{short!r} is not true or false")
    timeout_s = float(_number(source, "campaign.timeout_s", head.get("timeout_s", 900.0), 10.0, 86400.0))
    metrics = head.get("metrics", [])
    if not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics):
        raise _fail(source, "campaign.metrics", "is not a list of metric names")
    compare = head.get("compare")
    if compare is not None and (compare not in COMPARISONS or scenario_name not in COMPARISONS[compare]):
        raise _fail(source, "campaign.compare", f"{compare!r}: not a comparison for {scenario_name} "
                                                f"(known: {', '.join(f'{k} ({v})' for k, v in COMPARISONS.items())})")

    grid_raw = _only(source, "grid", raw.get("grid", {}), (*GRID_KEYS, "scale", *CONFIGS))
    grid: dict = {}
    for key, values in grid_raw.items():
        if key in CONFIGS:
            grid.update(_config_grid(source, key, values))
            continue
        if key == "scale":
            _only(source, "grid.scale", values, tuple(SCALES))
            for name, factors in values.items():
                where = f"grid.scale.{name}"
                grid[f"scale.{name}"] = [float(_number(source, where, f, *SCALE_RANGE)) for f in
                                         _list(source, where, factors)]
            continue
        values = _list(source, f"grid.{key}", values)
        kind = GRID_KEYS[key]
        if kind == "fault":                     # "" none, else FAULT:TARGET:PARAM[,...] as `hil run --inject`
            for value in values:
                if not isinstance(value, str):
                    raise _fail(source, f"grid.{key}", f"{value!r} is not a string")
                try:
                    parse_faults(value, "fault")
                except UserInputError as error:
                    raise _fail(source, f"grid.{key}", str(error)) from None
        elif kind is str:
            bad = [v for v in values if v not in scenario.controllers]
            if bad:
                raise _fail(source, f"grid.{key}", f"{bad[0]!r} is not run by {scenario_name} "
                                                   f"(it runs: {', '.join(scenario.controllers)})")
        else:
            integer = isinstance(kind[0], int) and isinstance(kind[1], int)
            values = [v if key == "time_scale" and v in PLANNED_TIME_SCALES else    # `hil run --time-scale auto`
                      _number(source, f"grid.{key}", v, *kind, integer=integer) for v in values]
        grid[key] = list(values)
    if "load_kg" in grid and not scenario.sweeps_loads:
        raise _fail(source, "grid.load_kg", f"{scenario_name} does not run at several loads (use payload_kg)")
    if "time_scale" in grid and not scenario.time_scalable:
        raise _fail(source, "grid.time_scale", f"{scenario_name} has no movement timing to scale")
    if "position_mm" in grid:
        try:
            scenario.check_positions(tuple(p * 1e-3 for p in grid["position_mm"]))
        except UserInputError as error:
            raise _fail(source, "grid.position_mm", str(error).removeprefix("--positions: ")) from None

    mc = _only(source, "montecarlo", raw.get("montecarlo", {}), ("draws", "seed", "scale"))
    draws = int(_number(source, "montecarlo.draws", mc.get("draws", 0), 0, 10_000, integer=True))
    draw_seed = int(_number(source, "montecarlo.seed", mc.get("seed", 1), 0, 2**31 - 1, integer=True))
    spreads = {name: float(_number(source, f"montecarlo.scale.{name}", v, *SPREAD_RANGE))
               for name, v in _only(source, "montecarlo.scale", mc.get("scale", {}), tuple(SCALES)).items()}
    if spreads and not draws:
        raise _fail(source, "montecarlo.draws", "0 draws with montecarlo.scale given")

    controller_config = raw.get("controller_config", {})
    emulator_config = raw.get("emulator_config", {})
    for name, sections in (("controller_config", controller_config), ("emulator_config", emulator_config)):
        if not isinstance(sections, dict):
            raise _fail(source, name, "is not a table of config sections")
        try:
            CONFIGS[name](None, sections or None)
        except UserInputError as error:
            raise _fail(source, name, str(error)) from None

    campaign = Campaign(name=str(head.get("name", path.stem)), scenario=scenario_name, short=short,
                        timeout_s=timeout_s, metrics=tuple(metrics), compare=compare, grid=grid, draws=draws,
                        draw_seed=draw_seed,
                        spreads=spreads, controller_config=controller_config, emulator_config=emulator_config,
                        source=source)
    count = (math.prod(len(v) for v in grid.values()) if grid else 1) * max(draws, 1)
    if count > MAX_RUNS:
        raise _fail(source, "grid", f"{count} runs (at most {MAX_RUNS})")
    nominal = emulator_raw_load(None, None)
    for run in campaign.runs()[:1]:            # the scaled keys exist and stay in range
        try:
            controller_config_load(None, campaign.controller_sections(run.params) or None)
            emulator_raw_load(None, campaign.emulator_sections(run.params, nominal))
        except UserInputError as error:
            raise _fail(source, "grid", str(error)) from None
    return campaign
