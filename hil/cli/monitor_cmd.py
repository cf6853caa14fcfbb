"""`hydrapod monitor`: the operator's live view of a bus, or the replay of a recorded log."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from program.cliutil import number_in_range, output_file
from program.errors import UserInputError
from protocol.bus import open_bus
from protocol.devices import DEVICE_PROFILES

SNAPSHOT_SIZE = (160, 48)          # columns, rows of the screen without a terminal
LIVE_NICE = 10                     # live: below the controller, the emulator and the HIL host


def _percentiles(values: list[float]) -> dict:
    """p50 / p99 / max of the per-second CPU figures (seconds that carried frames)."""
    if not values:
        return {}
    return {"p50": round(float(np.percentile(values, 50)), 1), "p99": round(float(np.percentile(values, 99)), 1),
            "max": round(max(values), 1), "seconds": len(values)}


def _summary(view, source, app, wall_s: float, cpu_s: float) -> dict:
    from hil.monitor.sources import ReplaySource
    s = view.snapshot()
    out = {"frames": s.frames, "unknown": s.unknown, "e2e_rejected": s.rejected, "lost": s.lost,
           "state": s.state, "fault": s.fault, "legs": s.n_legs, "ok_by_message": view.ok_by_message(),
           "rejected_by_message": view.rejected_by_message(), "source_error": source.error,
           "wall_s": round(wall_s, 2), "cpu_pct": round(100 * cpu_s / wall_s, 1),
           "cpu_pct_busy_seconds": _percentiles(app.cpu_seconds), "redraw_hz": round(app.redraw_hz(), 1)}
    if isinstance(source, ReplaySource):
        out.update(replay_log_s=round(source.log_span_s, 3), replay_wall_s=round(source.wall_s, 3),
                   replay_behind_max_ms=round(source.lag_s * 1e3, 1))
    return out


def _monitor(args: argparse.Namespace) -> int:
    if args.replay and args.bus:
        raise UserInputError("monitor: --bus and --replay exclude each other")
    if args.replay and args.control:
        raise UserInputError("monitor: --control needs a live bus, not --replay")
    if args.snapshot and not (args.replay or args.duration_s):
        raise UserInputError("monitor: --snapshot needs --replay (rendered at its end) or --duration-s")
    if args.headless and not args.duration_s:
        raise UserInputError("monitor: --headless needs --duration-s (nothing would end it)")
    if args.export_dir and not Path(args.export_dir).is_dir():
        raise UserInputError(f"monitor: --export-dir {args.export_dir}: no such directory")
    from hil.monitor.app import MonitorApp
    from hil.monitor.sources import CommandSender, LiveSource, ReplaySource, check_log
    from hil.monitor.view import BusView
    view = BusView(devices=args.devices)
    bus = None
    if args.replay:
        source = ReplaySource(view, check_log(args.replay), args.speed)
        pace = f"{args.speed:g}x" if args.speed > 0 else "full speed"
        title = f"hydrapod monitor: replay of {args.replay} at {pace}"
    else:
        bus = open_bus(args.bus, recorder=True)   # a large receive buffer: it loses nothing
        # beside a controller and an emulator on this host, the screen must never take their CPU
        os.nice(LIVE_NICE)
        source = LiveSource(view, bus)
        title = f"hydrapod monitor: {args.bus or 'default bus'}" + (" (control)" if args.control else " (read-only)")
    sender = CommandSender(view, bus) if args.control else None
    app = MonitorApp(view, source, title, sender=sender, snapshot=Path(args.snapshot) if args.snapshot else None,
                     duration_s=args.duration_s, export_dir=Path(args.export_dir or "."))
    wall, cpu = time.monotonic(), time.process_time()
    try:
        headless = bool(args.snapshot) or args.headless
        app.run(headless=headless, size=SNAPSHOT_SIZE if headless else None)
    finally:
        source.stop()
        if bus is not None:
            bus.shutdown()
    summary = _summary(view, source, app, time.monotonic() - wall, time.process_time() - cpu)
    if args.json:
        print(json.dumps(summary, indent=1))
    elif args.snapshot or args.headless:
        print(f"monitor: {summary['frames']} frames, {summary['e2e_rejected']} E2E rejected, "
              f"{summary['lost']} lost; controller {summary['state']} {summary['fault']}; "
              f"CPU {summary['cpu_pct']} %, redraw {summary['redraw_hz']} Hz"
              + (f"; replay {summary['replay_log_s']} s of log in {summary['replay_wall_s']} s, "
                 f"behind at most {summary['replay_behind_max_ms']} ms" if args.replay else ""))
    if source.error:
        sys.stderr.write(f"monitor: the source stopped: {source.error}\n")
        return 1
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("monitor", help="the operator's live view: controller, legs, platform, bus, EMCY "
                                       "(a live bus or a replayed log)")
    p.add_argument("--bus", metavar="SPEC", help="the bus to watch (default: socketcan:vcan0 if present, else the "
                                                 "default on-host multicast group)")
    p.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod",
                   help="the nodes' profile: the project's own (default) or stock CANopen devices, whose PDOs "
                        "are shown as the messages they stand for")
    p.add_argument("--replay", metavar="LOG", help="replay a recorded .blf or .asc log instead")
    p.add_argument("--speed", type=number_in_range(float, 0.0, 1000.0), default=1.0,
                   help="replay speed, times the log's own pace (0: as fast as it can; default 1)")
    p.add_argument("--control", action="store_true",
                   help="keys that send HOST_CMD: e E-STOP (at once), n enable, d disable, r reset (confirmed)")
    p.add_argument("--snapshot", metavar="FILE.svg", type=output_file,
                   help="render the screen to this SVG at the end of the replay (or of --duration-s) and exit")
    p.add_argument("--duration-s", type=number_in_range(float, 0.1, 86400.0, low_open=False), default=None,
                   help="exit after this many seconds")
    p.add_argument("--headless", action="store_true", help="no terminal (with --duration-s: a summary only)")
    p.add_argument("--export-dir", metavar="DIR", help="where x writes the visible window's CSV (default: .)")
    p.add_argument("--json", action="store_true", help="print the frame counts as JSON on exit")
    p.set_defaults(handler=_monitor)
