"""`hydrapod controller`: the controller daemon on a bus (and `python -m firmware_py`).

Runs until SIGTERM/SIGINT, then brings the valves to HOLD and DISABLED and exits 0 with a
one-line summary. Real-time measures (gc frozen and disabled, SCHED_FIFO, mlockall, CPU
affinity) are applied when permitted; each one that is not is logged and skipped.
"""

from __future__ import annotations

import json
import sys

from firmware_py.config import ControllerConfig, load_config
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from program.cliutil import StopFlag
from program.realtime import applied, cpu_latency_measure, freeze_gc, lock_memory, pin_cpu, set_fifo, thaw_gc

CLASSIC_BITRATE = 1e6                  # a classic CAN bus at its highest rate


def log(text: str) -> None:
    print(f"controller: {text}", file=sys.stderr, flush=True)


def realtime_setup(cfg: ControllerConfig, realtime: bool) -> list[str]:
    """GC frozen and disabled always, and the CPUs' wake-up latency (lockstep too: each cycle
    waits on the emulator's frames, and a halted CPU's wake-up costs every one of those);
    scheduling, memory locking and affinity for realtime."""
    freeze_gc(disable=True)
    if not realtime:
        return applied(cpu_latency_measure(cfg.timing.cpu_latency_us), log)
    measures = {f"SCHED_FIFO priority {cfg.timing.realtime_priority}": set_fifo(cfg.timing.realtime_priority),
                "mlockall": lock_memory()}
    if cfg.timing.cpu >= 0:
        measures[f"CPU {cfg.timing.cpu}"] = pin_cpu(cfg.timing.cpu)
    return applied({**measures, **cpu_latency_measure(cfg.timing.cpu_latency_us)}, log)


def realtime_teardown() -> None:
    thaw_gc()


def bus_budget_note(devices: str, n_legs: int, rate_hz: float, spec) -> str:
    """Stock devices on one bus: what their frames take of a 1 Mbit/s bus at this rate. More
    than the budget on a real interface is refused (one line, naming the rate one bus
    carries); on a virtual bus (multicast, in-process, a vcan interface: no bit timing) it is
    said and run."""
    if devices != "canopen":
        return ""
    from program.errors import UserInputError
    from protocol import canopen_layout
    from protocol.bus import default_bus_spec
    from protocol.busload import MAX_LOAD

    spec = spec or default_bus_spec()
    budget = canopen_layout.budgets(rate_hz, CLASSIC_BITRATE, n_legs, 1)[0]
    if budget["fits"]:
        return ""
    rate = canopen_layout.highest_rate(CLASSIC_BITRATE, n_legs, rate_hz)
    said = (f"--devices canopen at {rate_hz:g} Hz: the stock devices' frames need {100 * budget['total_load']:.1f} % "
            f"of a 1 Mbit/s bus (budget {100 * MAX_LOAD:g} %); one bus carries them at {rate:g} Hz at most "
            f"(`hydrapod bus-load --devices canopen`)")
    if spec.kind == "socketcan" and not spec.channel.startswith("vcan"):
        raise UserInputError(said + f": use --rate-hz {rate:g}")
    return said + f"; {spec} has no bit timing (virtual): run as asked"


def run_daemon(args) -> int:
    from firmware_py.controller import Controller
    from firmware_py.runtime.configure import ConfigurationError
    from firmware_py.runtime.identify import IdentityError
    from firmware_py.runtime.loop import ActivationError, ControllerLoop
    from firmware_py.runtime.sync import check_sync_source
    from protocol.bus import default_bus_spec, open_bus, parse_bus_spec

    spec = parse_bus_spec(args.bus) if args.bus is not None else None     # a bad string fails first
    cfg = load_config(args.config)
    check_sync_source(cfg.timing.sync_source, args.pacing, (spec or default_bus_spec()).kind == "socketcan")
    controller = Controller(cfg, args.rig, 1.0 / args.rate_hz, CONTROLLER_NAMES[args.controller])
    stop = StopFlag()
    budget_note = bus_budget_note(args.devices, controller.status.n_legs, args.rate_hz, spec)
    bus = open_bus(spec)
    loop = ControllerLoop(bus, controller, args.rate_hz, args.pacing, log=log, devices=args.devices)
    if budget_note:
        log(budget_note)
    bus.set_filters(loop.can_filters())               # the CAN controller's acceptance filter
    code = 0
    notes = realtime_setup(cfg, args.pacing == "realtime")
    if notes:
        log("real-time: " + ", ".join(notes))
    try:
        try:
            loop.activate(stop)
        except (IdentityError, ConfigurationError) as exc:     # a device the bus lacks, or refusing its setup
            log(f"activation refused: {exc}")
            code = 2
        except ActivationError as exc:
            log(f"activation failed: {exc}")
            code = 1
        else:
            loop.run(stop)
            loop.shutdown()
    finally:
        realtime_teardown()
        bus.shutdown()
    summary = loop.summary()
    if args.summary:
        with open(args.summary, "w") as handle:
            json.dump(summary, handle, indent=1)
    timing = summary["timing"].get("compute_us", {})
    print(f"controller: rig={controller.status.rig} controller={args.controller} pacing={args.pacing} "
          f"cycles={summary['cycles']} "
          f"overruns={summary['overruns']} e2e_errors={summary['e2e_errors']} "
          f"missing_frames={summary['missing_frames']} faults={summary['faults']} "
          f"fault_code={summary['fault_code']} state={summary['state']} "
          f"compute_p99_us={timing.get('p99', 'n/a')}", flush=True)
    return code
