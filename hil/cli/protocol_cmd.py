"""`hydrapod bus-load`, `hydrapod protocol dump`, `protocol bench`, `protocol configure` and
`protocol sync-check`."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict

from hil.tools.protocol_bench import format_bench, run_bench
from program.cliutil import number_in_range
from program.errors import UserInputError
from protocol import canopen_layout
from protocol.busload import MAX_LOAD, MIN_COMPUTE_WINDOW_US, bus_budget, format_budget
from protocol.codec import CODECS
from protocol.dbc import dbc_path
from protocol.devices import DEVICE_PROFILES, canopen_log_quiet
from protocol.nodes import LEGS_OF_RIG, RIGS

CLASSIC_CAN_MAX_BITRATE = 1_000_000


def add_parsers(sub) -> None:
    p = sub.add_parser("bus-load", help="worst-case bus load and cycle timeline from the DBC",
                       description="Bus load and cycle timeline on classic CAN of the DBC's schedule, or of "
                                   "the CANopen device profile's layout (protocol/devices/canopen-layout.toml, "
                                   "each device's PDOs from its EDS). Exit 0 if it fits the limits, 1 if not.")
    p.add_argument("--devices", choices=DEVICE_PROFILES, default="hydrapod",
                   help="hydrapod: the DBC's nodes (default); canopen: stock CiA 408/406/404 devices")
    p.add_argument("--rig", choices=RIGS, default="hexapod",
                   help="--devices canopen: the rig whose devices are budgeted (default hexapod)")
    p.add_argument("--buses", type=number_in_range(int, 1, 6), default=1,
                   help="--devices canopen: legs split in order across this many buses, one SYNC each (default 1)")
    p.add_argument("--rate-hz", type=number_in_range(float, 0, 10_000, low_open=True), default=500.0,
                   help="SYNC rate (default 500)")
    p.add_argument("--bitrate", type=number_in_range(int, 10_000, CLASSIC_CAN_MAX_BITRATE), default=1_000_000,
                   help="classic CAN bit rate in bit/s (default 1000000)")
    p.add_argument("--max-load", type=number_in_range(float, 0, 1, low_open=True), default=MAX_LOAD,
                   help=f"worst-case load limit (default {MAX_LOAD})")
    p.add_argument("--min-compute-us", type=number_in_range(float, 0), default=MIN_COMPUTE_WINDOW_US,
                   help=f"required compute window in us (default {MIN_COMPUTE_WINDOW_US:g})")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=cmd_bus_load)

    proto = sub.add_parser("protocol", help="protocol tools")
    psub = proto.add_subparsers(dest="protocol_command", required=True, metavar="{dump,bench,configure,sync-check}")
    d = psub.add_parser("dump", help="messages, schedule, E2E and signal scaling as compiled from the DBC")
    d.add_argument("--json", action="store_true", help="print JSON")
    d.set_defaults(handler=cmd_protocol_dump)
    b = psub.add_parser("bench", help="time the codec hot path (receive, encode, one cycle of frames)")
    b.add_argument("--iterations", type=number_in_range(int, 100, 10_000_000), default=20_000,
                   help="timed iterations per case (default 20000)")
    b.add_argument("--json", action="store_true", help="print JSON")
    b.set_defaults(handler=cmd_protocol_bench)
    c = psub.add_parser("configure", help="configure a rig's stock CANopen devices by SDO and read them back",
                        description="Write every stock device of the layout (protocol/devices/canopen-layout.toml) "
                                    "its PDOs by SDO in CiA 301's order, with the layout's SYNC start values, and "
                                    "read everything back. Exit 0 when every node holds it; a node that refuses, is "
                                    "silent or reads back otherwise: one line naming it and the object, exit 2.")
    c.add_argument("--bus", required=True, help="bus string (socketcan:can0, udp_multicast:..., virtual:NAME)")
    c.add_argument("--rig", choices=RIGS, default="hexapod", help="the rig whose devices are configured")
    c.add_argument("--sdo-timeout-ms", type=number_in_range(float, 1.0, 10_000.0), default=200.0,
                   help="a node silent this long after a request is named (default 200)")
    c.add_argument("--json", action="store_true", help="print JSON")
    c.set_defaults(handler=cmd_protocol_configure)
    k = psub.add_parser("sync-check", help="the kernel's SYNC on a SocketCAN interface: counters and period",
                        description="Start the SYNC as the controller does on SocketCAN (the kernel's broadcast "
                                    "manager repeating the counter sequence), receive it back and judge it from "
                                    "the kernel's receive stamps. Exit 0 when every counter came in order, 1 if "
                                    "not; the period's error is printed (a benchmark). Nothing else may send "
                                    "SYNC on the interface meanwhile.")
    k.add_argument("--bus", required=True, help="socketcan:<interface> (e.g. socketcan:can0)")
    k.add_argument("--rate-hz", type=number_in_range(float, 1.0, 10_000.0), default=500.0,
                   help="SYNC rate (default 500)")
    k.add_argument("--seconds", type=number_in_range(float, 0.1, 3600.0), default=2.0,
                   help="how long to listen (default 2)")
    k.add_argument("--json", action="store_true", help="print JSON")
    k.set_defaults(handler=cmd_protocol_sync_check)


def cmd_bus_load(args: argparse.Namespace) -> int:
    limits = {"max_load": args.max_load, "min_compute_us": args.min_compute_us}
    if args.devices == "hydrapod":
        if args.buses != 1:
            raise UserInputError(f"--buses {args.buses}: the hydrapod devices' DBC is one bus (--devices canopen "
                                 "splits the legs)")
        budget = bus_budget(args.rate_hz, args.bitrate, **limits)
        print(json.dumps(budget, indent=2) if args.json else format_budget(budget))
        return 0 if budget["fits"] else 1
    n_legs = LEGS_OF_RIG[args.rig]
    if args.buses > n_legs:
        raise UserInputError(f"--buses {args.buses}: the {args.rig} has {n_legs} leg(s)")
    budgets = canopen_layout.budgets(args.rate_hz, args.bitrate, n_legs, args.buses, **limits)
    plan = canopen_layout.split_plan(args.rate_hz, args.bitrate, n_legs, **limits)
    fits = all(b["fits"] for b in budgets)
    if args.json:
        print(json.dumps({"devices": "canopen", "rig": args.rig, "buses": budgets, "plan": plan}, indent=2))
        return 0 if fits else 1
    for k, budget in enumerate(budgets):
        legs = canopen_layout.legs_on_bus(n_legs, args.buses, k)
        extra = " with the IMU, the host and the controller's status" if k == 0 else ""
        print(f"# bus {k + 1} of {args.buses}: legs {legs[0]}-{legs[-1]}{extra}\n{format_budget(budget)}\n")
    print(format_plan(plan, args.bitrate))
    return 0 if fits else 1


def format_plan(plan: dict, bitrate: float) -> str:
    """What carries the CANopen layout (`canopen_layout.split_plan`), in words."""
    legs, rate = plan["n_legs"], plan["rate_hz"]
    head = f"CANopen devices, {legs} leg(s) at {rate:g} Hz, {bitrate:g} bit/s: "
    if plan["one_bus_fits"]:
        return head + "one bus carries them"
    lines = [head + "one bus does not carry them"]
    if plan["fewest_buses"]:
        split = " / ".join(f"legs {g[0]}-{g[-1]}" for g in plan["legs_per_bus"])
        lines.append(f"  {plan['fewest_buses']} buses do ({split}; one SYNC each, in phase): --buses "
                     f"{plan['fewest_buses']}")
    if plan["one_bus_rate_hz"] > 0:
        lines.append(f"  or one bus at {plan['one_bus_rate_hz']:g} Hz at most: --rate-hz {plan['one_bus_rate_hz']:g}")
    return "\n".join(lines)


def _describe() -> list[dict]:
    out = []
    for codec in CODECS.values():
        sched = codec.schedule
        out.append({
            "name": codec.name, "id": codec.frame_id, "dlc": codec.dlc, "sender": sched.sender,
            "kind": sched.kind, "sync_period": sched.sync_period, "sync_phase": sched.sync_phase,
            "cycle_time_ms": sched.cycle_time_ms, "e2e_data_id": codec.data_id,
            "signals": [asdict(s) for s in codec.signals],
        })
    return out


def cmd_protocol_dump(args: argparse.Namespace) -> int:
    messages = _describe()
    if args.json:
        print(json.dumps({"dbc": str(dbc_path()), "messages": messages}, indent=2))
        return 0
    print(f"# {dbc_path()}")
    for m in messages:
        when = {"cyclic": "every SYNC", "every_nth_sync": f"every {m['sync_period']}th SYNC, phase {m['sync_phase']}",
                "timer": f"every {m['cycle_time_ms']} ms", "event": "on event"}[m["kind"]]
        e2e = f"E2E P01 data id {m['e2e_data_id']:#06x}" if m["e2e_data_id"] is not None else "no E2E"
        print(f"\n{m['name']}  id {m['id']:#05x}  dlc {m['dlc']}  from {m['sender']}  {when}  {e2e}")
        for s in m["signals"]:
            kind = f"{'s' if s['signed'] else 'u'}{s['length']}@{s['start']}"
            print(f"  {s['name']:<18} {kind:<8} x{s['scale']:g}{s['offset']:+g} "
                  f"[{s['minimum']:g}, {s['maximum']:g}] {s['unit'] or '-':<6} {s['comment']}")
    return 0


def cmd_protocol_bench(args: argparse.Namespace) -> int:
    result = run_bench(args.iterations)
    print(json.dumps(result, indent=2) if args.json else format_bench(result))
    return 0


def cmd_protocol_configure(args: argparse.Namespace) -> int:
    import can
    import canopen

    from firmware_py.runtime.configure import ConfigurationError, configure
    from protocol.bus import open_bus, parse_bus_spec

    devices = canopen_layout.load_layout(LEGS_OF_RIG[args.rig])
    network = canopen.Network(open_bus(parse_bus_spec(args.bus)))
    network.notifier = can.Notifier(network.bus, network.listeners, timeout=0.05)

    def client_of(node: int):
        sdo = network.add_node(node, canopen.ObjectDictionary()).sdo
        sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = args.sdo_timeout_ms / 1e3, 1          # one request each
        return sdo

    try:
        with canopen_log_quiet():
            configure(client_of, devices)
    except ConfigurationError as error:
        raise UserInputError(f"protocol configure: {error}") from None
    finally:
        network.disconnect()
    rows = []
    for device in devices:
        for schedule in canopen_layout.device_schedules(device):
            if "PDO" in schedule.name:
                rows.append({"node": device.node, "pdo": schedule.name, "cob_id": schedule.frame_id,
                             "dlc": schedule.dlc, "every_nth_sync": schedule.sync_period,
                             "phase": schedule.sync_phase})
    if args.json:
        print(json.dumps({"rig": args.rig, "configured": rows}, indent=2))
        return 0
    print(f"configured and read back: {len(devices)} node(s) of the {args.rig}")
    for row in rows:
        print(f"  node {row['node']:3d}  {row['pdo']:<24} id {row['cob_id']:#05x}  dlc {row['dlc']}  "
              f"every {row['every_nth_sync']} SYNC(s), phase {row['phase']}")
    return 0


def cmd_protocol_sync_check(args: argparse.Namespace) -> int:
    from hil.tools.sync_check import format_sync_check, sync_check
    from protocol.bus import open_bus, parse_bus_spec
    from protocol.dbc import sync_counter_overflow

    spec = parse_bus_spec(args.bus)
    if spec.kind != "socketcan":
        raise UserInputError(f"--bus {args.bus}: the kernel's SYNC needs a SocketCAN interface (socketcan:<name>)")
    bus = open_bus(spec)
    try:
        doc = sync_check(bus, args.rate_hz, args.seconds, sync_counter_overflow())
    finally:
        bus.shutdown()
    print(json.dumps(doc, indent=2) if args.json else format_sync_check(doc))
    return 0 if doc["passed"] else 1
