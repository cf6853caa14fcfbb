"""`hydrapod controller`: the controller daemon (firmware_py's own options) and
`hydrapod controller bench`, the update step's compute time."""

from __future__ import annotations

import argparse
import json

from firmware_py.runtime.arguments import configure_parser
from program.cliutil import number_in_range


def _bench(args) -> int:
    from firmware_py.config import load_config
    from hil.tools.controller_bench import format_bench, run_bench
    from plant_emulator.params import load_config as load_emulator_config
    rows = run_bench(load_config(args.config), load_emulator_config(args.emulator_config), cycles=args.cycles)
    print(json.dumps({"update_step_us": rows}, indent=2) if args.json else format_bench(rows))
    return 0


def _alloc(args) -> int:
    from firmware_py.config import load_config
    from hil.tools.alloc_count import CounterBuildError, cycle_allocations, format_allocations
    from plant_emulator.params import load_config as load_emulator_config
    from program.errors import UserInputError
    try:
        rows = cycle_allocations(load_config(args.config), load_emulator_config(args.emulator_config), args.cycles)
    except CounterBuildError as error:
        raise UserInputError(str(error)) from None
    print(json.dumps({"allocations": rows}, indent=2) if args.json else format_allocations(rows))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    ctl = sub.add_parser("controller", help="the controller daemon (runs until SIGTERM/SIGINT); "
                                            "'controller bench' times the update step")
    configure_parser(ctl)
    ctl_sub = ctl.add_subparsers(dest="controller_command", required=False, metavar="SUBCOMMAND",
                                 parser_class=type(ctl))
    p = ctl_sub.add_parser("bench", help="compute time of the update step per controller and rig (p50/p99/max)")
    p.add_argument("--cycles", type=number_in_range(int, 100, 10_000_000), default=20000)
    p.add_argument("--config", metavar="FILE", help="controller TOML overriding the packaged defaults")
    p.add_argument("--emulator-config", metavar="FILE", help="emulator TOML for the rig it drives in process")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_bench)
    p = ctl_sub.add_parser("alloc", help="what a steady cycle allocates per controller and rig: NumPy buffers "
                                         "and Python object-allocator blocks (builds a small C hook with cc)")
    p.add_argument("--cycles", type=number_in_range(int, 100, 2800), default=2000)
    p.add_argument("--config", metavar="FILE", help="controller TOML overriding the packaged defaults")
    p.add_argument("--emulator-config", metavar="FILE", help="emulator TOML for the rig it drives in process")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_alloc)
