"""`hydrapod design ...`: the thesis's design work as commands (chapters 7.3-7.5.1).

    hydrapod design robustness [--plants SRC] [--nominal MM,KG] [--kp --ki] [--out DIR] [--json]
    hydrapod design schedule [--plants SRC] [--out FILE] [--ki-scale] [--kp-fraction] [--ti-fraction] [--json]
    hydrapod design modes [--pose X,Y,Z,ROLL,PITCH,YAW] [--payload-kg M] [--supply-bar P] [--along] [--sealed]
                          [--closed-loop] [--json] [--plot DIR]
    hydrapod design capacity [--movements M ...] [--payload-kg M ...] [--supply-bar P ...] [--time-scale S]
                             [--config FILE] [--json]
    hydrapod design computed-torque [--out FILE] [--supply-bar P] [--rigs LIST] [--samples N] [--refine N]
                                    [--seed S] [--min-damping Z] [--workers N] [--bandwidth-hz] [--damping]
                                    [--integral-fraction] [--velocity-gain] [--testbench-velocity-gain]
                                    [--force-bandwidth-hz] [--velocity-filter-hz] [--json]
    hydrapod design edge-moves [--moves N] [--seed S] [--workers W] [--json]
    hydrapod design tightness [--movements M ...] [--payload-kg M ...] [--supply-bar P ...] [--seed S]
                              [--controller-config FILE] [--workers N] [--json]
    hydrapod design sweep --key KEY --values V,V [--points nominal|envelope] [--movements M,M] [--seeds S,S]
                          [--workers N] [--json]

SRC: `table-a3` (the thesis's plants), `emulator` (the emulator's linearisation) or the
metrics.json of a `hil run sha-identification`.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from hil.design.sweep import MOVEMENTS
from physics.constants import BAR
from program.cliutil import number_in_range, output_dir, output_file
from program.errors import UserInputError

THESIS_KP_V_MM, THESIS_KI_V_MM_S = 0.085, 0.46      # chapter 7.4.2


def _plants(text: str) -> str:
    """argparse `type=`: a known source, or a file that exists (read later, errors one line)."""
    from hil.design.plants import SOURCES
    if text in SOURCES or Path(text).is_file():
        return text
    raise argparse.ArgumentTypeError(f"{text!r} is neither {' nor '.join(SOURCES)} nor an existing file")


def _subset(names: tuple[str, ...], noun: str):
    """argparse `type=`: a comma-separated, non-empty subset of `names`."""
    def parse(text: str) -> tuple[str, ...]:
        chosen = tuple(n.strip() for n in text.split(",") if n.strip())
        if not chosen or any(n not in names for n in chosen):
            raise argparse.ArgumentTypeError(f"{text!r}: {noun} are {' and '.join(names)}")
        return chosen
    return parse


_rigs = _subset(("hexapod", "testbench"), "rigs")


def _nominal(text: str) -> tuple[float, float]:
    """argparse `type=`: POSITION_MM,LOAD_KG."""
    try:
        position, load = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not POSITION_MM,LOAD_KG (e.g. 120,6)") from None
    return position, load


def _comma_list(kind: type, example: str, valid, rule: str):
    """argparse `type=`: comma-separated `kind` values, each `valid` (else `rule` is said)."""
    def parse(text: str) -> tuple:
        try:
            values = tuple(kind(v) for v in text.split(","))
        except ValueError:
            noun = "integers" if kind is int else "numbers"
            raise argparse.ArgumentTypeError(f"{text!r}: comma-separated {noun} (e.g. {example})") from None
        if not all(valid(v) for v in values):
            raise argparse.ArgumentTypeError(f"{text!r}: {rule}")
        return values
    return parse


_ki_scales = _comma_list(float, "0.2,0.1", lambda v: 0.0 < v <= 1.0, "each scale in (0, 1]")
_numbers = _comma_list(float, "0,40", math.isfinite, "finite numbers")
_seeds = _comma_list(int, "1,2,3", lambda v: v >= 0, "seeds >= 0")
_movements = _subset(MOVEMENTS, "movements")


def _computed_torque_key(text: str) -> str:
    """argparse `type=`: a [computed_torque] key of the controller's config."""
    from firmware_py.config import ComputedTorque
    keys = ComputedTorque.keys()
    if text not in keys:
        raise argparse.ArgumentTypeError(f"{text!r} is not a [computed_torque] key ({', '.join(sorted(keys))})")
    return text


def _edge_moves(args) -> int:
    from hil.design.edge_moves import edge_moves, format_edge_moves
    runs = edge_moves(args.moves, args.seed, args.workers)
    print(json.dumps([r.as_dict() for r in runs], indent=1) if args.json else format_edge_moves(runs))
    return 0


def _tightness(args) -> int:
    from hil.design.simulate import point_configs
    from hil.design.tightness import format_tightness, sweep_tightness
    for payload in args.payload_kg:         # a value the configs refuse: one line, before any run
        for supply in args.supply_bar:
            point_configs(payload, supply, config_path=args.controller_config)
    rows = sweep_tightness(args.movements, args.payload_kg, args.supply_bar, args.seed, args.workers,
                           args.controller_config)
    print(json.dumps([r.as_dict() for r in rows], indent=1) if args.json else format_tightness(rows))
    return 0


def _sweep(args) -> int:
    from hil.design.sweep import POINTS, format_sweep, sweep
    runs = sweep(args.key, args.values, POINTS[args.points], args.movements, args.seeds, args.workers)
    print(json.dumps([r.as_dict() for r in runs], indent=1) if args.json else format_sweep(args.key, runs))
    return 0


def _robustness(args) -> int:
    from hil.design.plants import plant_set
    from hil.design.reports import find_plant, format_robustness, plot_nyquist, plot_uncertainty, robustness_doc
    out = output_dir(args.out or "hil-out/design-robustness")
    plants = plant_set(args.plants)
    if args.nominal is not None and find_plant(plants, *args.nominal) is None:
        raise UserInputError(f"--nominal {args.nominal[0]:g},{args.nominal[1]:g}: no such plant in {args.plants} "
                             f"(positions {sorted({round(p.position_m * 1e3, 3) for p in plants})} mm, "
                             f"loads {sorted({p.load_kg for p in plants})} kg)")
    doc, arrays = robustness_doc(plants, args.plants, args.kp, args.ki, args.nominal)
    plot_uncertainty(arrays, out / "uncertainty.png")
    plot_nyquist(arrays, out / "nyquist.png")
    doc["figures"] = ["uncertainty.png", "nyquist.png"]
    (out / "robustness.json").write_text(json.dumps(doc, indent=1))
    text = format_robustness(doc)
    (out / "robustness.md").write_text(text + "\n![Multiplicative uncertainty](uncertainty.png)\n"
                                       "\n![Nyquist of the uncertain plant](nyquist.png)\n")
    print(json.dumps(doc, indent=1) if args.json else text + f"\n(written to {out})")
    # the verdict: the nominal loop internally stable and the small-gain test met
    return 0 if doc["pi"]["internally_stable"] and doc["uncertainty"]["robustly_stable"] else 1


def _adaptive_steps(args) -> int:
    from hil.design.adaptive_steps import adaptive_steps, format_steps, plot_steps
    out = output_dir(args.plot, "--plot") if args.plot is not None else None     # before minutes of work
    doc = adaptive_steps(args.ki_scales)
    if out is not None:
        figure = out / "adaptive_steps.png"
        plot_steps(doc, figure)
        doc["figures"] = [str(figure)]
    print(json.dumps(doc, indent=1) if args.json else format_steps(doc))
    return 0


def _schedule(args) -> int:
    from hil.design.plants import plant_set
    from hil.design.reports import format_schedule, plot_ki_detuning, schedule_doc
    from hil.design.schedule import schedule_toml, write_schedule
    out = Path(args.out)
    figures = output_dir(args.plot, "--plot") if args.plot is not None else None
    plants = plant_set(args.plants)
    doc, tunings = schedule_doc(plants, args.plants, args.kp_fraction, args.ti_fraction, args.ki_scale)
    write_schedule(out, schedule_toml(tunings, args.plants, args.ki_scale))
    doc["file"] = str(out)
    if figures is not None:
        figure = figures / "ki_detuning.png"
        plot_ki_detuning(tunings, figure)
        doc["figures"] = [str(figure)]
    print(json.dumps(doc, indent=1) if args.json else format_schedule(doc, str(out)))
    return 0 if doc["every_loop_stable_with_detuned_ki"] else 1


def _pose(text: str) -> tuple[np.ndarray, np.ndarray]:
    """argparse `type=`: X,Y,Z,ROLL,PITCH,YAW in mm and degrees."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y,Z,ROLL,PITCH,YAW (mm, deg; e.g. 0,0,631,0,0,0)")
    return np.array(values[:3]) * 1e-3, np.radians(values[3:])


def _modes(args) -> int:
    from firmware_py.mechanics.geometry import default_geometry
    from firmware_py.mechanics.workspace import check_poses
    from hil.design.closed_loop import format_closed
    from hil.design.modes import (
        along_movements,
        format_along,
        format_modes,
        format_sealed,
        modal_model,
        model_doc,
        plot_modes,
        pose_quaternion,
        sealed_doc,
        sealed_modes,
    )
    from plant_emulator.params import load_config
    geometry = default_geometry()
    position, rpy = args.pose if args.pose is not None else (geometry.home_position_m, np.zeros(3))
    report = check_poses(geometry, position, pose_quaternion(rpy))
    if not report.reachable[0]:
        raise UserInputError(f"--pose {', '.join(f'{v:g}' for v in np.r_[position * 1e3, np.degrees(rpy)])}: "
                             f"outside the hexapod's workspace")
    out = output_dir(args.plot, "--plot") if args.plot is not None else None
    cfg = load_config()
    supply = None if args.supply_bar is None else args.supply_bar * 1e5
    doc = model_doc(modal_model(cfg, position, rpy, args.payload_kg, supply))
    along = along_movements(cfg, args.payload_kg, supply) if args.along else None
    if along is not None:
        doc["along"] = along
    if args.sealed:
        doc["sealed"] = sealed_doc(sealed_modes(cfg, position, rpy, args.payload_kg, supply_pa=supply))
    if args.closed_loop:
        from hil.design.closed_loop import hexapod_closed_loop
        loop = hexapod_closed_loop(cfg, position, rpy, args.payload_kg, supply)
        doc["closed_loop"] = [m.as_dict() for m in loop.modes() if m.frequency_hz > 0.0]
    if out is not None:
        doc["figures"] = [str(out / name) for name in plot_modes(doc, along, out)]
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        print(format_modes(doc) + ("\n" + format_along(along) if along is not None else "")
              + ("\n" + format_sealed(doc["sealed"]) if args.sealed else "")
              + ("\n" + format_closed(doc["closed_loop"]) if args.closed_loop else ""))
    return 0 if doc["converged"] else 1


def _computed_torque(args) -> int:
    from firmware_py.config import load_config as load_controller_config
    from hil.design.ct_gains import (
        GAIN_RANGES,
        HEXAPOD_SEARCH,
        TESTBENCH_RANGES,
        TESTBENCH_SEARCH,
        design_gains,
        design_testbench_gains,
        operating_set,
    )
    from hil.design.valve_map import computed_torque_toml, force_rate_floor, valve_map
    from plant_emulator.params import load_config
    supply = {} if args.supply_bar is None else {"actuator": {"supply_pressure_bar": args.supply_bar}}
    cfg = load_config(overrides=supply or None)     # the map holds at the supply it was made at
    spool, pressure_a, pressure_b, unreachable = valve_map(cfg)
    models = operating_set(cfg)
    floor = force_rate_floor(cfg, spool, pressure_a, pressure_b, models)
    packaged = load_controller_config().raw["computed_torque"]       # an option not given keeps its value
    given = {"bandwidth_hz": args.bandwidth_hz, "damping": args.damping, "integral_fraction": args.integral_fraction,
             "velocity_gain_per_s": args.velocity_gain, "force_bandwidth_hz": args.force_bandwidth_hz,
             "velocity_filter_hz": args.velocity_filter_hz}
    gains = {key: packaged[key] if value is None else value for key, value in given.items()}
    gains |= {key: packaged[key] for key in TESTBENCH_RANGES}
    if args.testbench_velocity_gain is not None:
        gains["testbench_velocity_gain_per_s"] = args.testbench_velocity_gain
    gains["force_rate_floor_n_s_pct"] = round(floor / 100.0, 3)

    def progress(count, candidate):
        if not args.json:
            print(f"  {count:3d}: worst damping {candidate.damping:6.3f}, score {candidate.score:8.3f}", flush=True)
    design = {}
    def search(defaults):                          # an option given overrides the rig's default
        return tuple(default if value is None else value
                     for value, default in zip((args.samples, args.refine, args.seed), defaults))
    searching = args.samples != 0 and not any(value is not None for value in given.values())
    if searching and "hexapod" in args.rigs:       # derived from the models (ct_gains)
        samples, refine, seed = search(HEXAPOD_SEARCH)
        best, tried = design_gains(cfg, samples, refine, seed, args.min_damping, args.workers, progress, models,
                                   floor)
        design["hexapod"] = {**best.as_dict(), "candidates": len(tried)}
        gains |= {key: round(best.gains[key], 4) for key in GAIN_RANGES}
    if searching and "testbench" in args.rigs and args.testbench_velocity_gain is None:
        best, tried = design_testbench_gains(cfg, *search(TESTBENCH_SEARCH), args.workers, progress)
        design["testbench"] = {**best.as_dict(), "candidates": len(tried)}
        gains |= {key: round(best.gains[key], 4) for key in TESTBENCH_RANGES}
    source = f"the emulator's configuration at {cfg.actuator.supply_pressure_pa / BAR:g} bar"
    text = computed_torque_toml(spool, pressure_a, pressure_b, gains, source, cfg.actuator.supply_pressure_pa)
    if supply:                                     # the residuals' model and the supply check at it too
        text += f"\n[hydraulic_model]\nsupply_pressure_bar = {args.supply_bar:g}\n"
    out = Path(args.out)
    try:
        out.write_text(text)
    except OSError as error:
        raise UserInputError(f"--out {out}: cannot write ({error.strerror})") from None
    doc = {"file": str(out), "map_points": int(spool.size), "map_points_beyond_supply": unreachable,
           "gains": gains, "design": design}
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        how = "; ".join(f"{rig} derived from {d['candidates']} candidates (score {d['score']:.3f})"
                        for rig, d in design.items()) or "as given"
        print(f"computed-torque config written to {out}: valve map {spool.shape[0]} forces x {spool.shape[1]} "
              f"velocities ({unreachable} beyond the supply, held at the nearest reachable point); gains {how}: "
              + ", ".join(f"{k} {v:g}" for k, v in gains.items()) + "; load it with --controller-config or --config")
    return 0


def _capacity(args) -> int:
    from firmware_py.config import load_config
    from hil.design.capacity import format_utilisation, utilisation
    from hil.experiments import MOVEMENT_OVERRIDES
    cfg = load_config(args.config, overrides=MOVEMENT_OVERRIDES)      # as `hil run pm-*` configures it
    supplies = args.supply_bar or [cfg.hydraulic_model.supply_pressure_pa / BAR]
    rows = [utilisation(cfg, name, payload, supply, args.time_scale)
            for name in args.movements for payload in args.payload_kg for supply in supplies]
    print(json.dumps([r.as_dict() for r in rows], indent=1) if args.json else format_utilisation(rows))
    return 0


def _envelope_points(p: argparse.ArgumentParser, payloads_kg, payload_help: str, supplies_bar,
                     supply_help: str) -> None:
    """The thesis's movements at payloads x supplies (`design capacity`, `design tightness`)."""
    p.add_argument("--movements", nargs="+", choices=("circle", "diagonal"), default=["circle", "diagonal"])
    p.add_argument("--payload-kg", nargs="+", type=number_in_range(float, 0.0, 50.0), default=payloads_kg,
                   help=payload_help)
    p.add_argument("--supply-bar", nargs="+", type=number_in_range(float, 1.0, 400.0), default=supplies_bar,
                   help=supply_help)


def _workers_and_json(p: argparse.ArgumentParser, handler) -> None:
    """The in-process tools' processes, their JSON output and the handler."""
    p.add_argument("--workers", type=number_in_range(int, 1, 64), default=2, help="processes")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=handler)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    design = sub.add_parser("design", help="design tools: robustness of the PI, gain schedule (chapter 7), "
                                           "the hexapod's modes")
    design_sub = design.add_subparsers(dest="design_command", required=True, metavar="TOOL")
    plants_help = "table-a3 (default), emulator, or a sha-identification metrics.json"

    p = design_sub.add_parser("robustness", help="nominal plant, well-posedness, PI poles, W1, ||W1 T||inf, "
                                                 "robust performance (chapters 7.3-7.4)")
    p.add_argument("--plants", type=_plants, default="table-a3", help=plants_help)
    p.add_argument("--nominal", type=_nominal, default=None, metavar="MM,KG",
                   help="the nominal plant's set point (default: chosen by eq. 7.10)")
    p.add_argument("--kp", type=number_in_range(float, 0.0, 100.0, low_open=True), default=THESIS_KP_V_MM,
                   help="PI proportional gain, V/mm (default: the thesis's 0.085)")
    p.add_argument("--ki", type=number_in_range(float, 0.0, 1000.0), default=THESIS_KI_V_MM_S,
                   help="PI integral gain, V/(mm s) (default: the thesis's 0.46)")
    p.add_argument("--out", metavar="DIR", help="robustness.json, robustness.md, uncertainty.png, nyquist.png "
                                                "(default: hil-out/design-robustness)")
    p.add_argument("--json", action="store_true", help="print robustness.json")
    p.set_defaults(handler=_robustness)

    p = design_sub.add_parser("schedule", help="Ziegler-Nichols PI per plant, 0.2 Ki, the [adaptive] table "
                                               "the controller loads (chapter 7.5.1.1)")
    p.add_argument("--plants", type=_plants, default="table-a3", help=plants_help)
    p.add_argument("--out", type=output_file, default="hil-out/schedule.toml", metavar="FILE",
                   help="the controller config file to write (default: hil-out/schedule.toml)")
    p.add_argument("--ki-scale", type=number_in_range(float, 0.0, 1.0, low_open=True), default=0.2,
                   help="the Ki detuning (thesis: 0.2)")
    p.add_argument("--kp-fraction", type=number_in_range(float, 0.0, 1.0, low_open=True), default=0.45,
                   help="Kp = this x Ku (Ziegler-Nichols PI: 0.45)")
    p.add_argument("--ti-fraction", type=number_in_range(float, 0.0, 10.0, low_open=True), default=1.0 / 1.2,
                   help="Ti = this x Tu (Ziegler-Nichols PI: 1/1.2)")
    p.add_argument("--plot", metavar="DIR", default=None,
                   help="write ki_detuning.png here: the PI's steps per Ki scale (Fig. 7.12)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_schedule)

    p = design_sub.add_parser("adaptive-steps", help="the adaptive law's 10 mm steps per Ki scale on Table A.3's "
                                                     "plants and the emulated bench (chapter 7.6.1's < 14 %%)")
    p.add_argument("--ki-scales", type=_ki_scales, default=(0.2, 0.1), metavar="S,S",
                   help="scales on Table 7.2's Ki (default 0.2,0.1; the controller's [adaptive] ki_scale is 0.2)")
    p.add_argument("--plot", metavar="DIR", default=None, help="write adaptive_steps.png here")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_adaptive_steps)

    p = design_sub.add_parser("modes", help="the emulated hexapod's linearised modes at a pose: joint-space "
                                            "inertia, leg stiffness, flow gain, frequencies, damping, shapes")
    p.add_argument("--pose", type=_pose, default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                   help="platform pose in mm and degrees (default: home)")
    p.add_argument("--payload-kg", type=number_in_range(float, 0.0, 65.0), default=0.0,
                   help="mass on the platform (default 0)")
    p.add_argument("--supply-bar", type=number_in_range(float, 1.0, 40.0), default=None,
                   help="supply pressure (default: the emulator's, 25 bar)")
    p.add_argument("--along", action="store_true", help="also at every waypoint of both movements (11.3)")
    p.add_argument("--sealed", action="store_true",
                   help="also with the valves in HOLD (chambers sealed, seals in pre-sliding): what hex-kick measures")
    p.add_argument("--closed-loop", action="store_true",
                   help="also the closed loop's modes with the packaged computed-torque controller")
    p.add_argument("--plot", metavar="DIR", default=None, help="write modes.png (and modes_along.png) here")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_modes)

    p = design_sub.add_parser("computed-torque", help="the computed-torque controller: its valve map "
                                                      "from the emulator's model, and its gains")
    p.add_argument("--out", type=output_file, default="hil-out/computed_torque.toml", metavar="FILE",
                   help="the controller config file to write (default: hil-out/computed_torque.toml)")
    p.add_argument("--supply-bar", type=number_in_range(float, 1.0, 40.0), default=None,
                   help="the power unit's pressure to make the map at (default: the emulator's, 25 bar); "
                        "the file then sets [hydraulic_model] supply_pressure_bar to it")
    # a gain given is used as given (the others: the packaged controller.toml's); none: the search
    p.add_argument("--bandwidth-hz", type=number_in_range(float, 0.1, 50.0),
                   help="task-space loop: Kp = w^2, Kd = 2 zeta w")
    p.add_argument("--damping", type=number_in_range(float, 0.1, 5.0), help="zeta")
    p.add_argument("--integral-fraction", type=number_in_range(float, 0.0, 5.0), help="Ki = this x w^3")
    p.add_argument("--velocity-gain", type=number_in_range(float, 0.0, 1000.0),
                   help="joint error to commanded piston velocity, 1/s")
    p.add_argument("--testbench-velocity-gain", type=number_in_range(float, 0.0, 1000.0),
                   help="the same on the test bench's leg, 1/s (given: no search for the test bench)")
    p.add_argument("--force-bandwidth-hz", type=number_in_range(float, 0.0, 100.0),
                   help="each leg's force loop on its load cell (its gain scheduled on the leg's operating point)")
    p.add_argument("--samples", type=number_in_range(int, 0, 10000), default=None,
                   help="the gain search's random candidates (default: 64 hexapod, 256 test bench; 0: keep the "
                        "packaged gains; any gain given: no search)")
    p.add_argument("--refine", type=number_in_range(int, 0, 10000), default=None,
                   help="Nelder-Mead evaluations from the best candidate (default: 40 hexapod, 60 test bench)")
    p.add_argument("--seed", type=number_in_range(int, 0, 2**31 - 1), default=None,
                   help="the searches' seed (default: 1 hexapod, 3 test bench)")
    p.add_argument("--min-damping", type=number_in_range(float, 0.0, 1.0), default=0.15,
                   help="every closed-loop mode at least this damped over the operating set")
    p.add_argument("--workers", type=number_in_range(int, 1, 64), default=2, help="processes for the search")
    p.add_argument("--rigs", type=_rigs, default=("hexapod", "testbench"),
                   help="whose gains to derive: hexapod,testbench (default both; the other keeps the packaged)")
    p.add_argument("--velocity-filter-hz", type=number_in_range(float, 0.5, 200.0),
                   help="low-pass of the measured twist")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_computed_torque)

    p = design_sub.add_parser("edge-moves", help="random single moves at the capacity check's own edge (and 1.1, "
                                                 "1.2 x it), in process: faults, largest error and yaw")
    p.add_argument("--moves", type=number_in_range(int, 1, 1000), default=40, help="random moves (default 40)")
    p.add_argument("--seed", type=number_in_range(int, 0, 2**31 - 1), default=1, help="the moves' seed")
    _workers_and_json(p, _edge_moves)

    p = design_sub.add_parser("tightness", help="is the capacity check tight? per envelope point, in process: the "
                                                "plan, 15 %% faster (refused? saturating?), and the fastest timing "
                                                "that completes within 10 mm, the check opened")
    _envelope_points(p, [0.0, 1.5, 3.0, 4.5, 6.0], "payloads (default 0 1.5 3 4.5 6)", [20.0, 25.0, 40.0],
                     "power unit pressures (default 20 25 40)")
    p.add_argument("--seed", type=number_in_range(int, 0, 2**31 - 1), default=7, help="the sensors' noise seed")
    p.add_argument("--controller-config", metavar="FILE",
                   help="controller config sections over the packaged ones (e.g. [time_scaling] hold_ms = 0)")
    _workers_and_json(p, _tightness)

    p = design_sub.add_parser("sweep", help="one [computed_torque] key over values: the thesis's movements in "
                                            "process per envelope point and noise seed, IAE and largest error")
    p.add_argument("--key", type=_computed_torque_key, required=True, help="a [computed_torque] key, thesis units")
    p.add_argument("--values", type=_numbers, required=True, metavar="V,V", help="its values, e.g. 0,40")
    p.add_argument("--points", choices=("nominal", "envelope"), default="nominal",
                   help="nominal: 0 kg at 25 bar; envelope: 0 kg at 20 and 40 bar, 1.5 kg at 25, 3, 4.5 and 6 kg "
                        "at 40 (default nominal)")
    p.add_argument("--movements", type=_movements, default=MOVEMENTS, metavar="M,M",
                   help="circle, diagonal (default both)")
    p.add_argument("--seeds", type=_seeds, default=(1, 2, 3), metavar="S,S", help="sensor-noise seeds (default 1,2,3)")
    _workers_and_json(p, _sweep)

    p = design_sub.add_parser("capacity", help="what the legs can give against what the thesis's movements ask: "
                                               "the utilisation and lag at a time scale, and the fastest "
                                               "time scale the controller accepts (`hil run --time-scale auto`)")
    _envelope_points(p, [0.0], "payloads on the platform (default 0)", None,
                     "power unit pressures (default: the config's [hydraulic_model] supply_pressure_bar)")
    p.add_argument("--time-scale", type=number_in_range(float, 0.25, 8.0), default=1.0,
                   help="x the thesis's ta, tm (default 1)")
    p.add_argument("--config", metavar="FILE", default=None, help="controller TOML (its models, geometry)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_capacity)
