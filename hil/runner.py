"""`hydrapod hil run`: emulator and controller as separate processes on a fresh bus, this
process as the host and recorder, then the analysis of the recorded log alone.

Order of a run: open the bus and the recorder -> start the emulator -> start the controller
-> wait for READY -> the scenario's script -> SIGTERM the controller (valves HOLD, then
DISABLED; its last frames are recorded) -> SIGTERM the emulator -> close the log -> read
the log back and analyse it -> metrics.json, plots, report.md.
"""

from __future__ import annotations

import copy
import json
import secrets
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from hil.experiments import PLANNED_TIME_SCALES
from hil.host import Host, HostError, PlatformNotHeld
from hil.logdata import read_log
from hil.metrics import faults_in_windows
from hil.processes import Child, ChildFailed, describe_status
from hil.report import write_outputs
from hil.scenario import Scenario
from plant_emulator.params import LOCKSTEP_SYNC_TIMEOUT_PERIODS
from program.cliutil import output_dir
from program.errors import UserInputError
from program.realtime import freeze_gc, thaw_gc
from protocol.bus import BusSpec, default_bus_spec, open_bus, parse_bus_spec
from protocol.enums import Ack, Command, EmuCommand, EmuFault, Fault, State

LOG_NAME = "run.blf"
# Lockstep runs in bus time, as fast as the machine goes; the nodes' heartbeats still come
# every 100 ms of wall clock. On a slow machine (the SocketCAN VM without KVM) a busy
# emulator sent one 0.35 s late and the controller faulted HEARTBEAT_LOST. A dead node is
# still found, in 10 s.
LOCKSTEP_HEARTBEAT_TIMEOUT_MS = 10000.0
# Realtime on a shared, non-RT host: a SCHED_FIFO 2 ms sleeper here wakes 4-27 ms late a few
# times a minute, mostly on both CPUs at once, sometimes on one alone. The valves' own
# 3-period watchdog then trips on the machine, not on the controller. HIL runs widen it;
# the realtime scenarios report every SYNC gap the 3-period watchdog would have tripped on.
REALTIME_EMULATOR_SYNC_TIMEOUT_PERIODS = 25.0
START_TIMEOUT_S = 90.0                             # imports, kernels, MuJoCo, activation
START_TRIES = 3                                    # realtime: a start a machine stall faulted is recovered
RECOVERY_TRIES = 4                                 # realtime: a recovery a machine stall faulted is repeated


def merge_sections(base: dict, *overlays: dict) -> dict:
    """Config sections: each overlay's keys over the ones before it, section by section."""
    merged = {section: dict(values) for section, values in base.items()}
    for overlay in overlays:
        for section, values in overlay.items():
            merged.setdefault(section, {}).update(values)
    return merged


@dataclass
class RunOptions:
    out_dir: Path
    bus: str | None = None           # None: a fresh multicast group and port; "default": the default bus
    pacing: str | None = None        # None: the scenario's
    rate_hz: float = 500.0
    devices: str = "hydrapod"        # the rig's devices: the project's own nodes, or stock CANopen devices
    short: bool = False
    controllers: tuple[str, ...] | None = None
    loads: tuple[float, ...] | None = None    # kg; scenarios that sweep loads: these instead of the plan's
    positions_m: tuple[float, ...] | None = None   # scenarios that step at several positions: these instead
    inject: tuple[tuple[str, int, int], ...] = ()   # emulator faults (EMU_CTRL name, target, param) at the start
    duration_s: float | None = None  # realtime scenarios: how long
    valve_watchdog_periods: float | None = None   # realtime: the emulated valves' SYNC watchdog
    start_timeout_s: float = START_TIMEOUT_S       # a slow machine (a VM in software emulation) needs more
    plots: bool = True                             # False: metrics and report only (batch runs, slow machines)
    # the movements (pm-*): this many times the thesis's ta, tm; or the planner's (PLANNED_TIME_SCALES)
    time_scale: float | str | None = None
    # a controller config file's sections (e.g. `hydrapod design schedule`), over the
    # scenario's own overrides: validated by the caller before the run
    controller_config: dict = field(default_factory=dict)
    emulator_config: dict = field(default_factory=dict)     # sections over the scenario's emulator overrides
    notes: list[str] = field(default_factory=list)


def fresh_bus_spec() -> BusSpec:
    """A multicast group and UDP port of its own, so runs can go in parallel."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("", 0))
        port = sock.getsockname()[1]
    return BusSpec("udp_multicast", f"239.255.{secrets.randbelow(254) + 1}.{secrets.randbelow(254) + 1}", port)


def resolve_bus(text: str | None) -> BusSpec:
    if text is None:
        return fresh_bus_spec()
    if text == "default":
        return default_bus_spec()
    return parse_bus_spec(text)


def toml_sections(data: dict) -> str:
    """Config sections as TOML text (the sections of a config file: tables of scalars)."""
    lines = []
    for section, values in data.items():
        lines.append(f"[{section}]")
        for key, value in values.items():
            lines.append(f"{key} = {json.dumps(value)}")
    return "\n".join(lines) + "\n"


class Run:
    """What a scenario's script drives: the host, and the controller process (restartable)."""

    def __init__(self, scenario: Scenario, options: RunOptions, spec: BusSpec, out: Path):
        self.scenario, self.options, self.spec, self.out = scenario, options, spec, out
        self.pacing = options.pacing or scenario.pacing
        self.period_s = 1.0 / options.rate_hz
        self.short = options.short
        self.notes = options.notes
        self.children: list[Child] = []
        self.controller: Child | None = None
        self.host: Host | None = None
        self.start_retries: list[tuple[float, float]] = []    # wall-clock windows of recovered starts

    # -- children -------------------------------------------------------------------------
    def _watch(self) -> None:
        for child in self.children:
            child.check_alive()

    def valve_watchdog_periods(self) -> float:
        return self.options.valve_watchdog_periods or REALTIME_EMULATOR_SYNC_TIMEOUT_PERIODS

    def start_emulator(self) -> None:
        if self.pacing == "lockstep":
            watchdog = LOCKSTEP_SYNC_TIMEOUT_PERIODS
        else:
            watchdog = self.valve_watchdog_periods()
            self.notes.append(f"emulated valves' SYNC watchdog and the controller's stall fault: "
                              f"{watchdog:g} periods (--valve-watchdog-periods; docs/TIMING.md)")
        name = self._child_name("emulator")
        config = self.out / f"{name}.toml"
        # the scenario's load at start, under the user's --emulator-config (a payload set there
        # must not be overridden by a command-line load)
        load = {"testbench": {"load_kg": self.scenario.load_kg}} if self.scenario.rig == "testbench" else \
            {"hexapod": {"payload_kg": self.scenario.load_kg}}
        config.write_text(toml_sections(merge_sections(load, self.scenario.emulator_overrides,
                                                       self.options.emulator_config)))
        child = Child(name, ["-m", "plant_emulator", "--bus", str(self.spec), "--rig", self.scenario.rig,
                             "--rate-hz", str(self.options.rate_hz),
                             "--sync-watchdog-periods", f"{watchdog:g}", "--config", str(config),
                             "--summary", str(self.out / f"{name}.json"), "--pacing", self.pacing,
                             "--devices", self.options.devices], self.out)
        heartbeats = self.host.node_heartbeats
        child.start()                # realtime: it locks its memory and runs SCHED_FIFO itself
        self.children.append(child)
        # its boot-up heartbeats: the controller's 5 s activation window starts only then
        self.host.wait_until(lambda: self.host.node_heartbeats > heartbeats, 10**9,
                             what="the emulator's first heartbeat", wall_timeout_s=self.options.start_timeout_s)

    def _child_name(self, base: str) -> str:
        """"controller", then "controller-2" ... for a restarted one (its own logs and summary)."""
        count = sum(1 for child in self.children if child.name.split("-")[0] == base)
        return base if count == 0 else f"{base}-{count + 1}"

    def start_controller(self, controller: str, overrides: dict | None = None) -> None:
        merged = merge_sections(self.scenario.controller_overrides, self.options.controller_config, overrides or {})
        if self.pacing == "lockstep":
            merged.setdefault("timing", {}).setdefault("heartbeat_timeout_ms", LOCKSTEP_HEARTBEAT_TIMEOUT_MS)
        else:   # a stall the emulated valves ride out must not fault the controller either
            merged.setdefault("timing", {}).setdefault("stall_fault_periods", self.valve_watchdog_periods())
        name = self._child_name("controller")
        config = self.out / f"{name}.toml"
        config.write_text(toml_sections(merged))
        child = Child(name, ["-m", "firmware_py", "--bus", str(self.spec), "--rig", self.scenario.rig,
                             "--rate-hz", str(self.options.rate_hz), "--pacing", self.pacing,
                             "--controller", controller, "--config", str(config), "--devices", self.options.devices,
                             "--summary", str(self.out / f"{name}.json")], self.out)
        child.start()
        self.children.append(child)
        self.controller = child
        self.host.new_controller()
        # FAULT ends the wait too: a controller that faults while starting never gets READY
        started = time.time()
        self.host.wait_state(State.READY, State.FAULT, max_cycles=10**9, wall_timeout_s=self.options.start_timeout_s)
        for attempt in range(START_TRIES):
            if self.host.state is not State.FAULT:
                return
            try:
                name = Fault(self.host.fault_code).name
            except ValueError:
                name = f"code {self.host.fault_code}"
            if self.pacing != "realtime" or attempt == START_TRIES - 1:
                raise HostError(f"{controller}: the controller went to FAULT while starting ({name})")
            # realtime: a machine stall while the loop starts; recovered here, judged from the log
            self.notes.append(f"{controller}: the controller went to FAULT while starting ({name}); "
                              f"RESET + ENABLE")
            try:
                self.recover_from_fault()
            except HostError as error:
                self.notes.append(f"{controller}: recovery after the start: {error}")
            self.start_retries.append((started, time.time()))

    def stop_controller(self) -> None:
        """SIGTERM: the controller holds, disables and exits 0; its last frames are recorded."""
        child = self.controller
        if child is None:
            return
        child.terminate()
        give_up = time.monotonic() + 20.0
        while child.returncode is None and time.monotonic() < give_up:
            self.host.pump(0.02)
        code = child.wait(1.0)
        if code != 0:
            raise ChildFailed(f"{child.name} exited with status {describe_status(code)} after SIGTERM; "
                              f"stderr tail:\n{child.tail()}")
        self.controller = None

    def stop_all(self) -> None:
        errors = []
        try:
            self.stop_controller()
        except (ChildFailed, HostError) as error:
            errors.append(str(error))
        for child in self.children:
            if child.returncode is None:
                child.terminate()
                try:
                    code = child.wait(20.0)
                    if code != 0:
                        errors.append(f"{child.name} exited with status {describe_status(code)}; "
                                      f"stderr tail:\n{child.tail()}")
                except ChildFailed as error:
                    errors.append(str(error))
        # frames still in flight
        give_up = time.monotonic() + 0.3
        while time.monotonic() < give_up and self.host.pump(0.05) is not None:
            pass
        if errors:
            raise ChildFailed("\n".join(errors))

    def kill_all(self) -> None:
        for child in self.children:
            child.kill()

    # -- helpers for scripts -----------------------------------------------------------------
    def cycles(self, seconds: float) -> int:
        return max(int(round(seconds / self.period_s)), 1)

    def wait_s(self, seconds: float) -> None:
        self.host.wait_cycles(self.cycles(seconds))

    def select(self, controller: str) -> None:
        """SELECT_CONTROLLER. Realtime: refused BAD_STATE because a machine stall has just
        faulted the controller, it is recovered first (whether a stall caused the fault is
        judged from the log) and selected again."""
        try:
            self.host.command(Command.SELECT_CONTROLLER, CONTROLLER_NAMES[controller])
        except HostError as error:
            self.await_fault_shown(str(error))
            if self.pacing != "realtime" or self.host.state is not State.FAULT:
                raise
            self.notes.append(f"{controller}: fault {Fault(self.host.fault_code).name} before its selection (realtime; "
                              "whether a machine stall caused it is judged from the log): recovered")
            self.recover_from_fault()
            self.host.command(Command.SELECT_CONTROLLER, CONTROLLER_NAMES[controller])
        self.host.wait_until(lambda: self.host.controller == CONTROLLER_NAMES[controller], 200,
                             what=f"controller {controller} in CTRL_STATUS")

    def await_fault_shown(self, error: str | None) -> None:
        """After a refusal BAD_STATE: the FAULT that caused it reaches CTRL_STATUS up to 16
        cycles later; wait for it before judging whether a machine stall caused it."""
        if error is not None and "BAD_STATE" in error:
            self.host.wait_until(lambda: self.host.state is State.FAULT, self.cycles(0.1), what=None)

    def recover_from_fault(self) -> None:
        """After a FAULT: RESET (valves hold), drop what was queued, ENABLE (a leg left on an
        end stop is brought back inside the guard); READY again. Realtime: a recovery that a
        machine stall faulted again is repeated (noted), at most RECOVERY_TRIES times."""
        for attempt in range(1, RECOVERY_TRIES + 1):
            try:
                self._recover_once()
                return
            except HostError as error:
                self.await_fault_shown(str(error))
                if self.pacing != "realtime" or self.host.state is not State.FAULT or attempt == RECOVERY_TRIES:
                    raise
                self.notes.append(f"recovery attempt {attempt} faulted {Fault(self.host.fault_code).name} ({error}); "
                                  "repeated")

    def _recover_once(self) -> None:
        self.host.command(Command.RESET)
        self.host.wait_state(State.IDLE, max_cycles=self.cycles(2.0))
        self.host.command(Command.CLEAR_WAYPOINTS)
        self.enable()
        self.host.wait_state(State.READY, max_cycles=self.cycles(2.0))
        self.wait_s(1.0)

    def enable(self, within_s: float = 2.0) -> None:
        """ENABLE from IDLE. After a RESET the controller refuses it (BAD_STATE) until every
        sensor has reported again and its estimators restarted there: ask again until then."""
        give_up = time.monotonic() + within_s
        while True:
            result = self.host.command(Command.ENABLE, expect_ok=False)
            if result is Ack.ACCEPTED:
                return
            if result is Ack.BEYOND_CAPACITY:
                raise PlatformNotHeld("HOST_CMD ENABLE refused: BEYOND_CAPACITY (the legs cannot hold the platform "
                                      "where it is; its valves stay in HOLD)")
            if result is not Ack.BAD_STATE or self.host.state is not State.IDLE or time.monotonic() > give_up:
                raise HostError(f"HOST_CMD ENABLE refused: {result.name} (state "
                                f"{self.host.state.name if self.host.state else None})")
            self.wait_s(0.02)

    def wait_motion_done(self, max_s: float) -> None:
        """Until the controller is back in READY after a motion (CTRL_STATUS every 16 SYNC) that
        takes `max_s` on time, and what its online time scaling adds (CTRL_CLOCK)."""
        self.host.wait_until(lambda: self.host.state is State.RUNNING or self.host.state is State.HOMING,
                             self.cycles(1.0), what=None)
        self.host.wait_motion_end(self.cycles(max_s))


def run_scenario(scenario: Scenario, options: RunOptions) -> dict:
    """Run, record, analyse; returns the metrics document (also written to the out dir)."""
    if options.controllers:
        unknown = [c for c in options.controllers if c not in scenario.controllers]
        if unknown:
            raise UserInputError(f"--controllers: {unknown[0]!r} is not run by {scenario.name} "
                                 f"(it runs: {', '.join(scenario.controllers)})")
    if options.loads and not scenario.sweeps_loads:
        raise UserInputError(f"--loads: {scenario.name} does not run at several loads")
    if options.positions_m:
        scenario.check_positions(options.positions_m)
    scenario = copy.copy(scenario)                   # the registered instance keeps its defaults
    note = scenario.configure_for(scenario.controllers_for(options.controllers, options.short))
    if note:
        options.notes.append(note)
    if options.time_scale is not None:
        if not scenario.time_scalable:
            raise UserInputError(f"--time-scale: {scenario.name} has no movement timing to scale "
                                 f"(the pm-* scenarios have)")
        if options.time_scale in PLANNED_TIME_SCALES:
            scale, how = scenario.planned_time_scale(merge_sections(scenario.controller_overrides,
                                                                    options.controller_config),
                                                     thesis_where_it_fits=options.time_scale == "fit")
            options.notes.append(f"--time-scale {options.time_scale}: {scale:g} x the thesis's timing ({how})")
            scenario.time_scale, scenario.retime_on_refusal = scale, True
        else:
            scenario.time_scale = options.time_scale
    pacing = options.pacing or scenario.pacing
    if pacing not in scenario.pacings:
        raise UserInputError(f"--pacing {pacing}: {scenario.name} runs in {' or '.join(scenario.pacings)} pacing")
    spec = resolve_bus(options.bus)
    out = output_dir(options.out_dir)
    for stale in ("metrics.json", "report.md", LOG_NAME):
        (out / stale).unlink(missing_ok=True)
    for base in ("controller", "emulator"):       # a restarted child's files from an earlier run
        for stale in out.glob(f"{base}-[0-9]*.*"):
            stale.unlink(missing_ok=True)
    run = Run(scenario, options, spec, out)
    bus = open_bus(spec, recorder=True)
    run.host = Host(bus, str(out / LOG_NAME), watch=run._watch)
    failure = None
    started = time.monotonic()
    try:
        run.start_emulator()
        run.start_controller(scenario.first_controller(options.controllers, options.short))
        for fault, target, param in options.inject:      # a plant or sensor fault for the whole experiment
            run.host.emulator(EmuCommand.INJECT_FAULT, target=target, fault=EmuFault[fault], param=param)
            run.notes.append(f"injected {fault} on node {target} (param {param}) before the script")
        if pacing == "realtime":            # the recorder: no long collection while it records
            freeze_gc(disable=False)
        scenario.script(run)
        run.stop_all()
    except (ChildFailed, HostError) as error:
        failure = str(error)
        try:
            run.stop_all()
        except (ChildFailed, HostError) as late:
            failure += "\n" + str(late)
    except BaseException:
        run.kill_all()
        raise
    finally:
        run.kill_all()
        run.host.close()
        bus.shutdown()
        thaw_gc()
    wall_s = time.monotonic() - started
    log = read_log(out / LOG_NAME, options.devices)
    unexplained = faults_in_windows(log, run.period_s, run.start_retries)
    if unexplained:
        failure = (failure + "\n" if failure else "") + \
            f"the controller faulted {', '.join(unexplained)} while starting, with no machine stall before it"
    children = _children_summaries(run)
    diverged = _plant_diverged(children)
    if diverged:
        failure = (failure + "\n" if failure else "") + diverged
    doc = write_outputs(scenario, log, out, extra={
        "bus": str(spec), "pacing": pacing, "devices": options.devices,
        "short": options.short,
        "wall_time_s": round(wall_s, 1), "frames_sent_by_host": run.host.frames_sent,
        "frames_received_by_host": run.host.frames_received, "notes": run.notes,
        "children": children, "failure": failure}, rate_hz=options.rate_hz, plots=options.plots)
    return doc


def _children_summaries(run: Run) -> dict:
    out = {}
    for child in run.children:
        path = run.out / f"{child.name}.json"
        entry = {"exit_status": child.returncode, "summary_line": child.summary_line()}
        if path.is_file():
            try:
                entry["summary"] = json.loads(path.read_text())
            except ValueError:
                pass
        out[child.name] = entry
    return out


def _plant_diverged(children: dict) -> str | None:
    """The run's failure where an emulator's physics diverged: the log after it is not physics."""
    for name, entry in children.items():
        summary = entry.get("summary") or {}
        if summary.get("plant_unstable"):
            return (f"{name}: the emulated plant diverged at t = {summary['plant_unstable_first_s']:.3f} s "
                    f"({summary['plant_unstable']} periods diverged): the log from there on is not physics")
    return None


def analyze_log(scenario: Scenario, log_path: Path, out: Path, devices: str = "hydrapod",
                rate_hz: float = 500.0) -> dict:
    """`hydrapod hil analyze`: the same analysis on any recorded log (rig or emulator) made at
    `rate_hz`."""
    log = read_log(log_path, devices)
    output_dir(out)
    return write_outputs(scenario, log, out, extra={"analysed_log": str(log_path)}, rate_hz=rate_hz)

