"""The `hydrapod` command: one entry point, one subcommand per job.

Each module here contributes its subcommands through `add_parsers(subparsers)`, whose
parsers set `handler`; errors in user input are one line and exit code 2.
"""

from __future__ import annotations

import sys

from program.numba_cache import configure

configure()     # before any kernel is defined (see program/numba_cache.py)

from hil.cli import (  # noqa: E402
    campaign_cmd,
    controller_cmd,
    design_cmd,
    emulator_cmd,
    hil_cmd,
    kinematics_cmd,
    monitor_cmd,
    protocol_cmd,
)
from program.cliutil import OneLineArgumentParser, run  # noqa: E402

PROG = "hydrapod"


def build_parser() -> OneLineArgumentParser:
    parser = OneLineArgumentParser(prog=PROG, description="hydrapod: control system of a hydraulic 6-UPS "
                                                          "Stewart-Gough platform over CAN")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineArgumentParser,
                                metavar="COMMAND")
    for module in (protocol_cmd, controller_cmd, kinematics_cmd, emulator_cmd, hil_cmd, campaign_cmd, design_cmd,
                   monitor_cmd):
        module.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run(args.handler, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
