"""The controller daemon's command line (`python -m firmware_py`, `hydrapod controller`)."""

from __future__ import annotations

import argparse

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from program.cliutil import number_in_range, output_file
from protocol.devices import DEVICE_PROFILES
from protocol.enums import PACINGS
from protocol.nodes import RIGS


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """The daemon's options, on `python -m firmware_py` and `hydrapod controller` alike."""
    from firmware_py.runtime.daemon import run_daemon

    parser.add_argument("--bus", default=None, metavar="SPEC",
                        help="socketcan:<if> | udp_multicast:<group>[:<port>] | virtual:<name> "
                             "(default: socketcan:vcan0 if present, else an on-host multicast group)")
    parser.add_argument("--rig", choices=RIGS, default="testbench")
    parser.add_argument("--rate-hz", type=number_in_range(float, 1.0, 1000.0), default=500.0)
    parser.add_argument("--pacing", choices=PACINGS, default="realtime")
    parser.add_argument("--controller", choices=tuple(CONTROLLER_NAMES), default="pi")
    parser.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod",
                        help="the rig's devices: the project's own nodes (hydrapod, the DBC with E2E) or stock "
                             "CANopen devices (canopen: CiA 408 valves, CiA 406/404 sensors, each configured by "
                             "SDO from protocol/devices/canopen-layout.toml)")
    parser.add_argument("--config", metavar="FILE", help="controller TOML overriding the packaged defaults")
    parser.add_argument("--summary", metavar="FILE", type=output_file,
                        help="write the run's summary as JSON on exit")
    parser.set_defaults(handler=run_daemon)
