"""`python -m plant_emulator [options]`: the emulator process, as `hydrapod emulator`."""

import sys

from program.numba_cache import configure

configure()     # before any kernel is defined (see program/numba_cache.py)

from plant_emulator.process import configure_parser  # noqa: E402
from program.cliutil import OneLineArgumentParser, run  # noqa: E402

PROG = "python -m plant_emulator"


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog=PROG, description="hydrapod plant emulator: the valve-driver and sensor "
                                                          "nodes of a rig on a bus, until SIGTERM/SIGINT")
    configure_parser(parser)
    args = parser.parse_args(argv)
    return run(args.handler, args, PROG)


if __name__ == "__main__":
    sys.exit(main())
