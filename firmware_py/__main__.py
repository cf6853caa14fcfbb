"""`python -m firmware_py [options]`: the controller daemon, as `hydrapod controller`."""

import sys

from program.numba_cache import configure

configure()     # before any kernel is defined (see program/numba_cache.py)

from firmware_py.runtime.arguments import configure_parser  # noqa: E402
from program.cliutil import OneLineArgumentParser, run  # noqa: E402

PROG = "python -m firmware_py"


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog=PROG, description="hydrapod controller daemon")
    configure_parser(parser)
    args = parser.parse_args(argv)
    return run(args.handler, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
