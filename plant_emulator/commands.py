"""`hydrapod emulator ...`: run the plant emulator on a bus, calibrate it, bench it."""

from __future__ import annotations

import argparse
import json
import sys

from protocol.cliutil import number_in_range, output_file
from protocol.errors import UserInputError

from .params import load_config


def _config(args, rate_hz: float | None = None):
    overrides: dict = {}
    if getattr(args, "load_kg", None) is not None:
        overrides["testbench"] = {"load_kg": args.load_kg}
        overrides["hexapod"] = {"payload_kg": args.load_kg}
    if rate_hz is not None:
        overrides["nodes"] = {"sync_period_ms": 1000.0 / rate_hz}
    return load_config(args.config, overrides or None)


def _run(args) -> int:
    from protocol.bus import open_bus

    from .emulator import Emulator, StopFlag
    from .rigs import make_rig

    cfg = _config(args, args.rate_hz)
    rig = make_rig(args.rig, cfg)
    stop = StopFlag()
    bus = open_bus(args.bus)
    emulator = Emulator(bus, rig, cfg)
    try:
        emulator.run(stop)
    finally:
        bus.shutdown()
    summary = emulator.summary()
    if args.summary:
        with open(args.summary, "w") as handle:
            json.dump(summary, handle, indent=1)
    c = emulator.counters
    print(f"emulator: rig={rig.name} syncs={c.syncs} sim_time_s={rig.time_s:.3f} frames_in={c.frames_in} "
          f"frames_out={c.frames_out} e2e_errors={c.e2e_errors} valve_faults={c.valve_faults} "
          f"sync_sequence_errors={c.sync_sequence_errors} host_stalls={c.host_stalls} "
          f"host_stall_max_ms={c.host_stall_max_s * 1e3:.1f}", flush=True)
    return 0


def _calibrate(args) -> int:
    from . import calibration
    from .params import build

    cfg = _config(args)
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
    from .bench import bench_rig, format_bench
    from .rigs import RIGS
    names = [n.strip() for n in args.rigs.split(",") if n.strip()]
    bad = [n for n in names if n not in RIGS]
    if bad or not names:
        raise UserInputError(f"--rigs: unknown rig {bad[0] if bad else args.rigs!r} (known: {', '.join(RIGS)})")
    cfg = _config(args)
    rows = [bench_rig(name, cfg, args.seconds, args.rate_hz) for name in names]
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print(format_bench(rows))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    emu = sub.add_parser("emulator", help="plant emulator: run on a bus, calibrate, bench",
                         description="Run the plant emulator (valve-driver and sensor nodes of a rig) on a bus "
                                     "until SIGTERM/SIGINT; or calibrate / bench it.")
    emu.add_argument("--bus", default=None, help="bus string (default: socketcan:vcan0 if present, else the "
                                                 "on-host udp_multicast group)")
    emu.add_argument("--rig", choices=("testbench", "hexapod"), default="testbench")
    emu.add_argument("--load-kg", type=number_in_range(float, 0.0, 65.0), default=None,
                     help="external mass (test bench slide or platform payload)")
    emu.add_argument("--rate-hz", type=number_in_range(float, 10.0, 2000.0), default=None,
                     help="SYNC rate the controller runs at (default: the config's sync_period_ms)")
    emu.add_argument("--config", metavar="FILE", help="TOML overriding data/emulator.toml")
    emu.add_argument("--summary", metavar="FILE", type=output_file, help="write the exit counters as JSON")
    emu.set_defaults(handler=_run)
    esub = emu.add_subparsers(dest="emulator_command", metavar="{calibrate,bench}",
                              parser_class=type(emu))

    p = esub.add_parser("calibrate", help="the emulator's b0, b1, k01 beside Table A.3")
    p.add_argument("--config", metavar="FILE", help="TOML overriding data/emulator.toml")
    p.add_argument("--fit", metavar="PARAMS", help="first tune these comma-separated parameters "
                                                     "(edge_flow, supply_lap, return_lap, volume_a, ...)")
    p.add_argument("--max-evaluations", type=number_in_range(int, 1, 100000), default=300)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_calibrate)

    p = esub.add_parser("bench", help="simulated seconds per wall second of each rig")
    p.add_argument("--config", metavar="FILE", help="TOML overriding data/emulator.toml")
    p.add_argument("--rigs", default="testbench,hexapod", help="comma-separated rigs")
    p.add_argument("--seconds", type=number_in_range(float, 0.01, 3600.0), default=5.0, help="simulated seconds")
    p.add_argument("--rate-hz", type=number_in_range(float, 10.0, 2000.0), default=500.0)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_bench)


def main(argv: list[str] | None = None) -> int:
    """`python -m plant_emulator [args]` = `hydrapod emulator [args]`."""
    from hil.cli import main as hydrapod_main
    return hydrapod_main(["emulator", *(sys.argv[1:] if argv is None else argv)])
