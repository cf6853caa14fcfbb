"""`python -m firmware_py [options]`: the controller daemon, as `hydrapod controller`."""

import sys

from protocol.cliutil import OneLineArgumentParser, run

from .commands import configure_controller_parser

PROG = "python -m firmware_py"


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog=PROG, description="hydrapod controller daemon")
    configure_controller_parser(parser)
    args = parser.parse_args(argv)
    return run(args.handler, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
