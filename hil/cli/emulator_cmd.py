"""`hydrapod emulator`: run the plant emulator on a bus (its own options), calibrate it
against Table A.3, bench its rigs."""

from __future__ import annotations

import argparse
import json

from plant_emulator.process import RIGS, configure_parser
from program.cliutil import number_in_range
from program.errors import UserInputError


def _calibrate(args) -> int:
    from hil.design import calibration
    from plant_emulator.params import build, load_config

    cfg = load_config(args.config)
    tuned = None
    if args.fit:
        names = args.fit.split(",")
        unknown = [n for n in names if n not in calibration.TUNABLE]
        if unknown:
            raise UserInputError(f"--fit: unknown parameter {unknown[0]!r} "
                                 f"(tunable: {', '.join(calibration.TUNABLE)})")
        raw, _ = calibration.fit(cfg.raw, names, args.max_evaluations)
        cfg = build(raw)
        tuned = {f"{section}.{key}": raw[section][key]
                 for section, key, *_ in (calibration.TUNABLE[n] for n in names)}
    table = calibration.calibration_table(cfg)
    report = {"method": "linearisation of the emulator's equations at rest holding the load "
                        "(sliding-regime friction slopes); b0, b1 from the dominant pole pair, k01 by a "
                        "least-squares fit of the 3rd-order velocity response over 5-300 rad/s",
              "tolerance": calibration.TOLERANCE, "pole_region": {"re": calibration.POLE_RE, "im": calibration.POLE_IM},
              "summary": calibration.summary(table), "points": table}
    if tuned:
        report["tuned"] = tuned
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    print(calibration.format_table(table))
    if tuned:
        print("tuned:", ", ".join(f"{k} = {v:.4g}" for k, v in tuned.items()))
    return 0


def _bench(args) -> int:
    from hil.tools.emulator_bench import bench_rig, format_bench
    from plant_emulator.params import load_config
    names = [n.strip() for n in args.rigs.split(",") if n.strip()]
    bad = [n for n in names if n not in RIGS]
    if bad or not names:
        raise UserInputError(f"--rigs: unknown rig {bad[0] if bad else args.rigs!r} (known: {', '.join(RIGS)})")
    cfg = load_config(args.config)
    rows = [bench_rig(name, cfg, args.seconds, args.rate_hz) for name in names]
    print(json.dumps(rows, indent=1) if args.json else format_bench(rows))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    emu = sub.add_parser("emulator", help="plant emulator: run on a bus, calibrate, bench",
                         description="Run the plant emulator (valve-driver and sensor nodes of a rig) on a bus "
                                     "until SIGTERM/SIGINT; or calibrate / bench it.")
    configure_parser(emu)
    esub = emu.add_subparsers(dest="emulator_command", metavar="{calibrate,bench}", parser_class=type(emu))
    p = esub.add_parser("calibrate", help="the emulator's b0, b1, k01 beside Table A.3")
    p.add_argument("--config", metavar="FILE", help="TOML overriding the emulator's data/emulator.toml")
    p.add_argument("--fit", metavar="PARAMS", help="first tune these comma-separated parameters "
                                                     "(edge_flow, supply_lap, return_lap, volume_a, ...)")
    p.add_argument("--max-evaluations", type=number_in_range(int, 1, 100000), default=300)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_calibrate)

    p = esub.add_parser("bench", help="simulated seconds per wall second of each rig")
    p.add_argument("--config", metavar="FILE", help="TOML overriding the emulator's data/emulator.toml")
    p.add_argument("--rigs", default="testbench,hexapod", help="comma-separated rigs")
    p.add_argument("--seconds", type=number_in_range(float, 0.01, 3600.0), default=5.0, help="simulated seconds")
    p.add_argument("--rate-hz", type=number_in_range(float, 10.0, 2000.0), default=500.0)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_bench)
