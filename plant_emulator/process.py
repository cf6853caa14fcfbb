"""The emulator process's command line (`python -m plant_emulator`, `hydrapod emulator`):
run the nodes of a rig on a bus until SIGTERM/SIGINT, then print a one-line summary."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from plant_emulator.params import LOCKSTEP_SYNC_TIMEOUT_PERIODS, ConfigError, load_config
from program.cliutil import StopFlag, number_in_range, output_file
from program.realtime import applied, cpu_latency_measure, freeze_gc, lock_memory, set_fifo
from program.sections import read_toml
from protocol.devices import DEVICE_PROFILES
from protocol.enums import PACINGS
from protocol.nodes import RIGS


def load_run_config(args) -> object:
    """The config file with the command line's overrides (load, SYNC rate, watchdog: in
    lockstep, unless the command line or the file sets it, longer than the controller's
    wait for a cycle's frames)."""
    overrides: dict = {}
    if getattr(args, "load_kg", None) is not None:
        overrides["testbench"] = {"load_kg": args.load_kg}
        overrides["hexapod"] = {"payload_kg": args.load_kg}
    nodes = {}
    if getattr(args, "rate_hz", None) is not None:
        nodes["sync_period_ms"] = 1000.0 / args.rate_hz
    if getattr(args, "sync_watchdog_periods", None) is not None:
        nodes["sync_timeout_periods"] = args.sync_watchdog_periods
    elif getattr(args, "pacing", None) == "lockstep" and not _file_sets(args.config, "nodes", "sync_timeout_periods"):
        nodes["sync_timeout_periods"] = LOCKSTEP_SYNC_TIMEOUT_PERIODS
    if nodes:
        overrides["nodes"] = nodes
    return load_config(args.config, overrides or None)


def _file_sets(path: str | None, section: str, key: str) -> bool:
    """Whether the user's config file declares `[section] key` (it wins over a default)."""
    return path is not None and key in read_toml(Path(path), ConfigError).get(section, {})


def realtime_setup(cfg) -> list[str]:
    """Memory locked, SCHED_FIFO at the config's priority and the CPUs' wake-up latency;
    returns what was applied and logs each measure that is not permitted (never fatal)."""
    measures = {"mlockall": lock_memory(),
                f"SCHED_FIFO priority {cfg.nodes.realtime_priority}": set_fifo(cfg.nodes.realtime_priority),
                **cpu_latency_measure(cfg.nodes.cpu_latency_us)}
    return applied(measures, _log)


def _log(text: str) -> None:
    print(f"emulator: {text}", file=sys.stderr, flush=True)


def run(emulator, bus, should_stop) -> None:
    """The process's loop: receive and handle frames until `should_stop()`, the nodes' timers
    between them; a wake-up later than a SYNC period (the process was not scheduled) pauses
    the nodes' clocks (`Emulator.pause_node_clocks`)."""
    emulator.boot()
    period = emulator.cfg.nodes.sync_period_s
    wait = 0.0
    while not should_stop():
        timeout = min(max(wait, 0.0005), 0.05)
        wake = emulator.clock() + timeout
        msg = bus.recv(timeout=timeout)
        received = emulator.clock()
        if received - wake > period:                         # woken this late: not scheduled
            emulator.pause_node_clocks(received - wake)
        if msg is not None:
            emulator.handle(msg)
            busy = emulator.clock() - received
            if busy > period:                                # a stall inside the handling
                emulator.pause_node_clocks(busy)
        wait = emulator.poll()


def run_emulator(args) -> int:
    from plant_emulator.emulator import Emulator
    from plant_emulator.rigs import make_rig
    from protocol.bus import open_bus, parse_bus_spec

    spec = parse_bus_spec(args.bus) if args.bus is not None else None     # a bad string fails first
    cfg = load_run_config(args)
    rig = make_rig(args.rig, cfg)
    stop = StopFlag()
    bus = open_bus(spec)
    emulator = Emulator(bus, rig, cfg, pacing=args.pacing, devices=args.devices)
    bus.set_filters(emulator.can_filters())   # the nodes' CAN controllers' acceptance filters
    # started: what start-up built leaves the collector's scans, so a collection in the run is short
    freeze_gc(disable=False)
    if args.pacing == "realtime":
        realtime_setup(cfg)
    else:                                   # lockstep: its SYNC handling waits on the controller's frames
        applied(cpu_latency_measure(cfg.nodes.cpu_latency_us), _log)
    try:
        run(emulator, bus, stop)
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


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """The run options, on `python -m plant_emulator` and `hydrapod emulator` alike."""
    parser.add_argument("--bus", default=None, help="bus string (default: socketcan:vcan0 if present, else the "
                                                    "on-host udp_multicast group)")
    parser.add_argument("--rig", choices=RIGS, default="testbench")
    parser.add_argument("--load-kg", type=number_in_range(float, 0.0, 65.0), default=None,
                        help="external mass (test bench slide or platform payload)")
    parser.add_argument("--rate-hz", type=number_in_range(float, 10.0, 2000.0), default=None,
                        help="SYNC rate the controller runs at (default: the config's sync_period_ms)")
    parser.add_argument("--sync-watchdog-periods", type=number_in_range(float, 1.0, 10000.0), default=None,
                        help="the valves' SYNC watchdog, in SYNC periods of wall clock (default: the config's "
                             f"[nodes].sync_timeout_periods, 3; with --pacing lockstep "
                             f"{LOCKSTEP_SYNC_TIMEOUT_PERIODS:g}, longer than the controller's wait for a "
                             "cycle's frames)")
    parser.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod",
                        help="the nodes: the project's DBC nodes (hydrapod), or stock CANopen devices as "
                             "protocol/devices/canopen-layout.toml places them (canopen: CiA 408 valves, CiA 406 "
                             "encoders, CiA 404 measuring devices, each configured by SDO from its EDS)")
    parser.add_argument("--config", metavar="FILE", help="TOML overriding the emulator's data/emulator.toml")
    parser.add_argument("--summary", metavar="FILE", type=output_file, help="write the exit counters as JSON")
    parser.add_argument("--pacing", choices=PACINGS, default="realtime",
                        help="the controller's --pacing (said at start when the controller's CTRL_STATUS "
                             "differs). realtime: once started, lock the process's memory (mlockall) and run "
                             "SCHED_FIFO at [nodes].realtime_priority (each logged when not permitted); "
                             "lockstep: normal priority, the valves' SYNC watchdog long")
    parser.set_defaults(handler=run_emulator)
