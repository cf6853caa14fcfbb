"""The `hydrapod` command: one entry point, one subcommand per job.

Each package contributes its subcommands through an `add_parsers(subparsers)` function
whose parsers set `handler`; errors in user input are one line and exit code 2.
"""

from __future__ import annotations

import sys

from firmware_py import commands as firmware_commands
from hil import commands as hil_commands
from hil.design import commands as design_commands
from plant_emulator import commands as emulator_commands
from protocol import commands as protocol_commands
from protocol.cliutil import OneLineArgumentParser, run

PROG = "hydrapod"


def build_parser() -> OneLineArgumentParser:
    parser = OneLineArgumentParser(prog=PROG, description="hydrapod: control system of a hydraulic 6-UPS "
                                                          "Stewart-Gough platform over CAN")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineArgumentParser,
                                metavar="COMMAND")
    protocol_commands.add_parsers(sub)
    firmware_commands.add_parsers(sub)
    emulator_commands.add_parsers(sub)
    hil_commands.add_parsers(sub)
    design_commands.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run(args.handler, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
