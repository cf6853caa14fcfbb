"""`hydrapod hil ...`: run a scenario, analyse a log, list the scenarios."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from physics.actuator import PAYLOAD
from physics.constants import MM
from program.cliutil import number_in_range, output_dir
from program.errors import UserInputError
from protocol.devices import DEVICE_PROFILES


def _scenario(name: str):
    from hil.scenarios import SCENARIOS
    if name not in SCENARIOS:
        raise UserInputError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    return SCENARIOS[name]


TIME_SCALES = number_in_range(float, 0.5, 10.0)
RATES_HZ = number_in_range(float, 100.0, 1000.0)
RATE_HELP = ("the loop's rate: SYNCs per second and the emulator's step (default 500, the thesis's; stock "
             "devices on one real bus carry 342 at most, `hydrapod bus-load --devices canopen`)")
DEVICES_HELP = ("the rig's devices, for the emulator and the controller alike: the project's own nodes "
                "(hydrapod, default) or stock CANopen devices (canopen: CiA 408 valves, CiA 406/404 sensors)")


def _time_scale(text: str) -> float | str:
    """--time-scale: a number within TIME_SCALES' range, or one of PLANNED_TIME_SCALES."""
    from hil.experiments import PLANNED_TIME_SCALES
    return text if text in PLANNED_TIME_SCALES else TIME_SCALES(text)


def _controllers(text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in CONTROLLER_NAMES]
    if bad or not names:
        raise UserInputError(f"--controllers: unknown controller {bad[0] if bad else text!r} "
                             f"(known: {', '.join(CONTROLLER_NAMES)})")
    return names


def _number_list(text: str, option: str, valid, what: str) -> tuple[float, ...]:
    """Comma-separated numbers, each `valid`; else one line naming the item."""
    values = []
    for item in text.split(","):
        try:
            value = float(item)
        except ValueError:
            value = float("nan")
        if not valid(value):
            raise UserInputError(f"{option}: {item.strip()!r} is not {what}")
        values.append(value)
    return tuple(values)


def _loads(text: str | None) -> tuple[float, ...] | None:
    """Comma-separated masses in kg, each within what EMU_CTRL's LOAD_MASS carries."""
    if text is None:
        return None
    from protocol.codec import CODECS
    signal = CODECS["EMU_CTRL"].signals[CODECS["EMU_CTRL"].index["LOAD_MASS"]]
    return _number_list(text, "--loads", lambda kg: signal.minimum <= kg <= signal.maximum,
                        f"a mass in {signal.minimum:g}..{signal.maximum:g} {signal.unit}")


def _positions(text: str | None) -> tuple[float, ...] | None:
    """Comma-separated working positions in mm, as metres (the scenario checks their range)."""
    if text is None:
        return None
    return tuple(mm * MM for mm in _number_list(text, "--positions", math.isfinite, "a stroke in mm"))


def _inject(text: str | None) -> tuple[tuple[str, int, int], ...]:
    from hil.injection import parse_faults
    return parse_faults(text)


def _finish(args, doc: dict) -> int:
    from hil.report import format_budget, format_terminal
    print(json.dumps(doc, indent=1, default=str) if args.json else format_terminal(doc))
    if getattr(args, "profile", False) and not args.json:
        print(format_budget(doc) or "no cycle budget: no process summary was written")
    return 0 if doc["passed"] else 1


def _run(args) -> int:
    from hil.runner import RunOptions, run_scenario
    scenario = _scenario(args.scenario)
    out = Path(args.out) if args.out else Path("hil-out") / scenario.name
    options = RunOptions(out_dir=out, bus=args.bus, pacing=args.pacing, rate_hz=args.rate_hz, devices=args.devices,
                         short=args.short,
                         controllers=_controllers(args.controllers), loads=_loads(args.loads),
                         positions_m=_positions(args.positions), inject=_inject(args.inject),
                         duration_s=args.duration_s, plots=not args.no_plots,
                         valve_watchdog_periods=args.valve_watchdog_periods, start_timeout_s=args.start_timeout_s,
                         controller_config=_controller_config(args.controller_config),
                         emulator_config=_emulator_config(args.emulator_config), time_scale=args.time_scale)
    for name, path, sections in (("controller", args.controller_config, options.controller_config),
                                 ("emulator", args.emulator_config, options.emulator_config)):
        if path:
            options.notes.append(f"{name} config {path}: [{'], ['.join(sections)}] over the scenario's own")
    return _finish(args, run_scenario(scenario, options))


def _controller_config(path: str | None) -> dict:
    """The file's sections, after the controller's own validation (one line, exit 2, naming
    the file and key); the controller process validates it again when it starts."""
    from firmware_py.config import load_config
    return _config_sections(path, load_config)


def _emulator_config(path: str | None) -> dict:
    """As `_controller_config`, for the emulator (the plant: payload, supply, parameters)."""
    from plant_emulator.params import load_config
    return _config_sections(path, load_config)


def _config_sections(path: str | None, validate) -> dict:
    if path is None:
        return {}
    from program.sections import read_toml
    validate(path)
    return read_toml(Path(path))


def _faults(args) -> int:
    from hil.faults import format_terminal, run_matrix
    out = output_dir(args.out or Path("hil-out") / "faults")
    doc = run_matrix(out, short=args.short, bus=args.bus, start_timeout_s=args.start_timeout_s,
                     pacings=(args.pacing,) if args.pacing else ("lockstep", "realtime"), payload_kg=args.payload_kg,
                     devices=args.devices)
    print(json.dumps(doc, indent=1, default=str) if args.json else format_terminal(doc))
    return 0 if doc["passed"] else 1


def _soak(args) -> int:
    from hil.runner import RunOptions, run_scenario
    from hil.scenarios.soak import Soak
    scenario = Soak(seconds=args.minutes * 60.0, seed=args.seed)
    out = Path(args.out) if args.out else Path("hil-out") / "soak"
    options = RunOptions(out_dir=out, bus=args.bus, rate_hz=500.0, valve_watchdog_periods=args.valve_watchdog_periods,
                         start_timeout_s=args.start_timeout_s)
    return _finish(args, run_scenario(scenario, options))


def _fuzz(args) -> int:
    from hil.fuzz import TARGETS, as_dicts, format_reports, run
    targets = [t.strip() for t in args.targets.split(",") if t.strip()]
    bad = [t for t in targets if t not in TARGETS]
    if bad or not targets:
        raise UserInputError(f"--targets: unknown target {bad[0] if bad else args.targets!r} "
                             f"(known: {', '.join(TARGETS)})")
    reports = run(targets, args.frames, args.seed)
    print(json.dumps(as_dicts(reports), indent=1) if args.json else format_reports(reports))
    return 0 if all(r.ok for r in reports) else 1


def _analyze(args) -> int:
    from hil.runner import analyze_log
    scenario = _scenario(args.scenario)
    log = Path(args.log)
    out = Path(args.out) if args.out else log.parent
    return _finish(args, analyze_log(scenario, log, out, args.devices, args.rate_hz))


def _list(args) -> int:
    from hil.scenarios import SCENARIOS
    rows = [{"name": s.name, "rig": s.rig, "pacing": s.pacing, "controllers": list(s.controllers),
             "thesis": s.chapter, "title": s.title} for s in SCENARIOS.values()]
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        for r in rows:
            print(f"{r['name']:<20} {r['rig']:<10} {r['pacing']:<9} {','.join(r['controllers']):<20} "
                  f"{r['thesis']:<22} {r['title']}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    hil = sub.add_parser("hil", help="hardware-in-the-loop: thesis experiments against the emulator, log analysis")
    hil_sub = hil.add_subparsers(dest="hil_command", required=True, metavar="SUBCOMMAND", parser_class=type(hil))
    p = hil_sub.add_parser("run", help="run a scenario: emulator + controller processes, this process as host")
    p.add_argument("scenario", metavar="SCENARIO")
    p.add_argument("--bus", metavar="SPEC",
                   help="bus to run on (default: a fresh on-host multicast group and port; 'default' = "
                        "socketcan:vcan0 if present, else the default group)")
    p.add_argument("--pacing", choices=("lockstep", "realtime"), default=None,
                   help="default: the scenario's (lockstep, realtime for the timing scenarios)")
    p.add_argument("--out", metavar="DIR", help="output directory (default: hil-out/SCENARIO)")
    p.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod", help=DEVICES_HELP)
    p.add_argument("--rate-hz", type=RATES_HZ, default=500.0, help=RATE_HELP)
    p.add_argument("--short", action="store_true", help="the short variant (what make test runs)")
    p.add_argument("--controllers", metavar="LIST", help="comma-separated subset of the scenario's controllers")
    p.add_argument("--loads", metavar="LIST",
                   help="comma-separated loads in kg, for the scenarios that run at several (sha-step, sha-tracking)")
    p.add_argument("--positions", metavar="LIST",
                   help="comma-separated working positions in mm, for the scenarios that step at several (sha-step)")
    p.add_argument("--inject", metavar="LIST",
                   help="emulator faults for the whole experiment, FAULT:TARGET:PARAM[,...] "
                        "(e.g. SEAL_LEAK:1:10; the DBC's EMU_CTRL.FAULT names)")
    p.add_argument("--duration-s", type=number_in_range(float, 1.0, 86400.0), default=None,
                   help="realtime scenarios: seconds of running (default 60; 10 with --short)")
    p.add_argument("--time-scale", type=_time_scale, default=None,
                   help="pm-circle, pm-diagonal: the movement at this many times the thesis's ta and tm "
                        "(default 1: the thesis's timing), or auto: the fastest the controller accepts "
                        "with the declared payload and supply, or fit: the thesis's timing where the "
                        "controller accepts it, else auto's")
    p.add_argument("--valve-watchdog-periods", type=number_in_range(float, 1.0, 10000.0), default=None,
                   help="realtime: the emulated valves' SYNC watchdog in periods (default 25 on a shared host; "
                        "3 is the valves' own, for an RT kernel)")
    p.add_argument("--controller-config", metavar="FILE",
                   help="controller config sections over the scenario's (e.g. from `hydrapod design schedule`)")
    p.add_argument("--emulator-config", metavar="FILE",
                   help="emulator config sections over the scenario's (payload, supply pressure, plant parameters)")
    p.add_argument("--start-timeout-s", type=number_in_range(float, 1.0, 3600.0), default=90.0,
                   help="how long the processes may take to come up (default 90; a VM without KVM needs more)")
    p.add_argument("--no-plots", action="store_true", help="metrics and report without the PNG figures")
    p.add_argument("--json", action="store_true", help="print metrics.json instead of the summary")
    p.add_argument("--profile", action="store_true",
                   help="print the cycle budget too: each phase of the controller's cycle and of the "
                        "emulator's SYNC handling (also in report.md)")
    p.set_defaults(handler=_run)
    p = hil_sub.add_parser("faults", help="the fault-injection matrix: every case in its own emulator + "
                                          "controller session, reaction times and excursions from the log")
    p.add_argument("--out", metavar="DIR", help="output directory (default: hil-out/faults)")
    p.add_argument("--short", action="store_true", help="every case on the hexapod, a subset on the test bench "
                                                        "(what make test runs)")
    p.add_argument("--bus", metavar="SPEC", help="as for run (default: a fresh on-host multicast group per session)")
    p.add_argument("--pacing", choices=("lockstep", "realtime"), default=None,
                   help="only the sessions of this pacing (default: both)")
    p.add_argument("--start-timeout-s", type=number_in_range(float, 1.0, 3600.0), default=90.0)
    p.add_argument("--payload-kg", type=number_in_range(float, *PAYLOAD.range), default=0.0,
                   help="a payload on the hexapod's platform, declared to its controller (default 0)")
    p.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod",
                   help=DEVICES_HELP + "; on canopen the cases an E2E check judges are not run")
    p.add_argument("--json", action="store_true", help="print faults.json instead of the table")
    p.set_defaults(handler=_faults)
    p = hil_sub.add_parser("soak", help="realtime hexapod trajectory loop with random frame faults: jitter, "
                           "overruns, faults, recoveries, log completeness")
    p.add_argument("--minutes", type=number_in_range(float, 0.1, 10080.0), default=1.0,
                   help="how long (default 1)")
    p.add_argument("--seed", type=number_in_range(int, 0, 2**63 - 1), default=20161,
                   help="the random faults' seed (default 20161)")
    p.add_argument("--out", metavar="DIR", help="output directory (default: hil-out/soak)")
    p.add_argument("--bus", metavar="SPEC", help="as for run (default: a fresh on-host multicast group)")
    p.add_argument("--valve-watchdog-periods", type=number_in_range(float, 1.0, 10000.0), default=None,
                   help="the emulated valves' SYNC watchdog and the controller's stall fault (default: as for run)")
    p.add_argument("--start-timeout-s", type=number_in_range(float, 1.0, 3600.0), default=90.0)
    p.add_argument("--json", action="store_true", help="print metrics.json instead of the summary")
    p.set_defaults(handler=_soak)
    p = hil_sub.add_parser("fuzz", help="random frames into the controller's receive side and the decoders: "
                                        "zero exceptions, every frame counted")
    p.add_argument("--frames", type=number_in_range(int, 1, 10**10), default=1_000_000,
                   help="frames per target (default 1000000)")
    p.add_argument("--seed", type=number_in_range(int, 0, 2**63 - 1), default=20161,
                   help="generator seed (default 20161, as make test)")
    p.add_argument("--targets", default="decoder,controller", help="comma-separated: decoder, controller")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_fuzz)
    p = hil_sub.add_parser("analyze", help="the scenario's analysis on a recorded log (BLF or ASC), e.g. from the rig")
    p.add_argument("log", metavar="LOG")
    p.add_argument("--scenario", required=True)
    p.add_argument("--out", metavar="DIR", help="where metrics.json, plots and report.md go (default: beside LOG)")
    p.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod", help=DEVICES_HELP)
    p.add_argument("--rate-hz", type=RATES_HZ, default=500.0, help="the rate the log was recorded at (default 500)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_analyze)
    p = hil_sub.add_parser("list", help="the scenarios")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_list)
