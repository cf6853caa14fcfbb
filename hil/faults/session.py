"""One session of the fault matrix: an emulator and controller pair on one rig and pacing,
running its cases in turn. Each case starts at rest at home with the controller READY, runs
the probe move (up 30 mm, back, 1.5 s each), injects its fault INJECT_AT_S into it, observes,
and ends with RESET + ENABLE and a move home that must run normally (case 9). The process
cases (SIGKILL, SIGSTOP, a dead emulator) need realtime pacing and a short valve SYNC
watchdog; the frame and plant cases run in lockstep (the same cycles every run)."""

from __future__ import annotations

import math
import os
import signal
import time
from dataclasses import replace
from pathlib import Path

from firmware_py.mechanics.geometry import default_geometry
from hil.faults.cases import (
    INJECT_AT_S,
    OBSERVE_S,
    PROBE_ACCEL_S,
    PROBE_RISE_M,
    PROBE_SEGMENT_S,
    SETTLE_S,
    STALL_S,
    TRY_LIMIT,
    Case,
    CaseKind,
    CaseResult,
    Marks,
)
from hil.faults.judge import JUDGES
from hil.host import HostError
from hil.logdata import LogData
from hil.logquery import LogView
from hil.metrics import faults_in_windows
from hil.processes import ChildFailed
from hil.scenario import Analysis, Check, Scenario
from protocol.codec import CODECS
from protocol.enums import Command, EmuCommand, EmuFault, Fault, NmtCommand, State, WaypointFlag
from protocol.nodes import LEGS_OF_RIG, rig_nodes
from protocol.outbox import Outbox


class Session(Scenario):
    """One emulator + controller pair running a list of cases."""

    def __init__(self, rig: str, pacing: str, cases: list[Case]):
        self.rig, self.pacing, self.pacings = rig, pacing, (pacing,)
        n_legs = 6 if rig == "hexapod" else 1
        # the test bench has one leg: a case aimed at leg 2-6 hits its only one
        self.cases = [c if c.target <= n_legs else replace(c, target=1, what=c.what.replace(f"leg {c.target}", "leg 1"))
                      for c in cases if rig in c.rigs]
        if rig == "testbench":
            self.cases = [replace(c, **c.on_testbench) for c in self.cases]
        self.name = f"faults-{rig}-{pacing}"
        self.title = f"fault-injection matrix, {rig}, {pacing}"
        self.chapter = "reliability (docs/PROTOCOL.md, supervisor)"
        self.controllers = ("model-based",) if rig == "hexapod" else ("adaptive",)
        self.marks: list[Marks] = []
        self.results: list[CaseResult] = []
        self._run = None                           # the run being scripted (its children's files)
        geometry = default_geometry()
        self.home = tuple(geometry.home_position_m) if rig == "hexapod" else (0.0, 0.0, 0.150)
        self.up = (self.home[0], self.home[1], self.home[2] + PROBE_RISE_M)

    # -- host side -------------------------------------------------------------------------
    def script(self, run) -> None:
        self.marks.clear()
        self._run = run                            # the children's summaries, for the analysis
        for case in self.cases:
            earlier: list[str] = []
            for attempt in range(TRY_LIMIT):
                if attempt:                        # the spoiled attempt stays in the log, not in the table
                    spoiled_mark = self.marks.pop()
                    own = spoiled_mark.notes[len(earlier):]
                    earlier.append(f"attempt {attempt}: " + "; ".join(own))
                mark = Marks(case, notes=list(earlier))
                self._ready(run, mark)
                try:
                    spoiled = self.run_case(run, mark)
                except (HostError, ChildFailed) as error:
                    mark.notes.append(f"host: {error}")
                    mark.extra["host_error"] = str(error)
                    run.await_fault_shown(str(error))
                    # realtime: a machine stall can fault the controller between READY and the
                    # probe's first waypoint (refused BAD_STATE): that attempt is spoiled too
                    spoiled = run.pacing == "realtime" and run.host.state is State.FAULT \
                        and math.isnan(mark.t_inject)
                mark.t_end = time.time()
                self.marks.append(mark)
                if not spoiled:
                    break
                mark.notes.append("the controller faulted before the injection "
                                  "(a machine stall tripped the stall watchdog); repeated")
            if run.host.state is not State.READY or case.kind in (CaseKind.KILL, CaseKind.KILL_EMULATOR):
                self._recover(run, mark)
            else:                                  # no fault: nothing to recover from but a fault that
                run.host.emulator(EmuCommand.CLEAR_ALL)    # lasts until cleared (random frame loss)
                run.wait_s(SETTLE_S)

    def _ready(self, run, mark: Marks) -> None:
        """READY at rest at home."""
        host = run.host
        if host.state is not State.READY:
            mark.notes.append(f"not READY before the case ({host.state.name if host.state else None}): recovered")
            self._recover(run, mark)
        run.wait_s(0.2)

    def _recover(self, run, mark: Marks) -> None:
        """Case 9: clear the injected faults, RESET, ENABLE, back home; READY again.

        Realtime: a machine stall during the recovery trips the stall watchdog (OVERRUN), or
        starves the controller of its sensor frames; a recovery that faulted is repeated (noted),
        up to TRY_LIMIT times, and the analysis fails it unless the log shows a machine stall
        before each of those faults (`metrics.faults_in_windows`).
        """
        host = run.host
        cleared = time.monotonic()
        host.emulator(EmuCommand.CLEAR_ALL)
        run.wait_s(0.1)
        # a node the case silenced is back (its heartbeat) before the RESET judges the nodes:
        # lockstep runs the cycles faster than its 100 ms heartbeat
        try:
            host.wait_heartbeats(cleared, {CODECS[f"HEARTBEAT_{n}"].frame_id for n in rig_nodes(LEGS_OF_RIG[self.rig])})
        except HostError as error:                 # the RESET below then says what is missing
            mark.notes.append(f"recovery: {error}")
        for attempt in range(1, TRY_LIMIT + 1):
            started = time.time()
            ok, error = self._recover_once(run)
            run.await_fault_shown(error)
            faulted = not ok and run.pacing == "realtime" and host.state is State.FAULT
            if error is not None:
                mark.notes.append(f"recovery: {error}")
            if not faulted or attempt == TRY_LIMIT:
                break
            mark.extra.setdefault("retried", []).append((started, time.time()))
            mark.notes.append(f"recovery attempt {attempt} faulted {Fault(host.fault_code).name}; repeated")
        mark.extra["recovered"] = ok

    def _recover_once(self, run) -> tuple[bool, str | None]:
        host = run.host
        try:
            if host.state in (State.FAULT, State.ESTOP):
                host.command(Command.RESET)
                host.wait_state(State.IDLE, max_cycles=run.cycles(2.0))
            if host.state is State.IDLE:
                host.command(Command.CLEAR_WAYPOINTS)
                run.enable()
                host.wait_state(State.READY, max_cycles=run.cycles(2.0))
            run.wait_s(0.3)
            host.waypoint(self.home, segment_time_s=PROBE_SEGMENT_S, accel_time_s=PROBE_ACCEL_S,
                          flags=WaypointFlag.LAST | WaypointFlag.START)
            run.wait_motion_done(PROBE_SEGMENT_S + 2.0)
            run.wait_s(SETTLE_S)
            return host.state is State.READY, None
        except HostError as error:
            return False, str(error)

    def _probe(self, run, mark: Marks) -> None:
        """Up and back, queued; returns INJECT_AT_S into the first segment."""
        host = run.host
        mark.t_start = time.time()
        host.waypoint(self.up, segment_time_s=PROBE_SEGMENT_S, accel_time_s=PROBE_ACCEL_S,
                      flags=WaypointFlag.LAST | WaypointFlag.START)
        mark.extra["probe_seq"] = (host.waypoint_seq - 1) % 256
        host.waypoint(self.home, segment_time_s=PROBE_SEGMENT_S, accel_time_s=PROBE_ACCEL_S,
                      flags=WaypointFlag.LAST | WaypointFlag.START)
        run.wait_s(INJECT_AT_S)

    def _finish_probe(self, run) -> None:
        """To the probe's end, or a fault and OBSERVE_S of holding (the excursion window)."""
        rest = 2 * PROBE_SEGMENT_S - INJECT_AT_S
        if run.host.wait_until(lambda: run.host.state in (State.FAULT, State.ESTOP), run.cycles(rest + 0.3),
                               what=None):
            run.wait_s(OBSERVE_S)
        else:
            run.wait_s(0.5)

    def _inject(self, run, mark: Marks) -> None:
        c = mark.case
        mark.t_inject = time.time()
        run.host.emulator(EmuCommand.INJECT_FAULT, target=c.target, fault=EmuFault[c.fault], param=c.param)

    def run_case(self, run, mark: Marks) -> bool:
        """Inject and observe; True when a machine stall spoiled it before the injection."""
        c, host = mark.case, run.host
        if c.kind is CaseKind.WAYPOINTS:
            self._bad_waypoints(run, mark)
            return False
        self._probe(run, mark)
        if host.state is State.FAULT:
            return run.pacing == "realtime"
        if c.kind is CaseKind.BASELINE:
            self._finish_probe(run)
            # realtime: nothing was injected, so an OVERRUN is the machine's stall (3 periods)
            return run.pacing == "realtime" and host.state is State.FAULT
        elif c.kind in (CaseKind.TRANSIENT, CaseKind.PERSISTENT, CaseKind.PLANT):
            self._inject(run, mark)
            self._finish_probe(run)
        elif c.kind is CaseKind.ESTOP:
            mark.t_inject = time.time()
            host.command(Command.ESTOP)
            run.wait_s(OBSERVE_S)
        elif c.kind is CaseKind.BABBLE:
            self._inject(run, mark)
            self._finish_probe(run)
        elif c.kind is CaseKind.REBOOT:           # from the node's boot-up: when the reset took effect
            node = encoder_node(c.target, LEGS_OF_RIG[self.rig])
            host.booted_at.pop(node, None)
            reset_node(host, node)
            host.wait_until(lambda: node in host.booted_at, run.cycles(0.5), what=f"node {node}'s boot-up")
            mark.t_inject = host.booted_at[node]
            self._finish_probe(run)
        elif c.kind is CaseKind.STALL:
            child = run.controller
            mark.t_inject = time.time()
            os.kill(child.proc.pid, signal.SIGSTOP)
            _pump_for(host, STALL_S)
            os.kill(child.proc.pid, signal.SIGCONT)
            mark.extra["t_cont"] = time.time()
            host.wait_until(lambda: host.state is State.FAULT, run.cycles(1.0), what=None)
            run.wait_s(OBSERVE_S)                  # held: no motion without a reset
        elif c.kind is CaseKind.KILL:
            child = run.controller
            child.stopping = True
            mark.t_inject = time.time()
            child.proc.kill()
            child.proc.wait()
            _pump_for(host, OBSERVE_S)             # the plant runs on; EMCY and EMU_TRUTH recorded
            run.controller = None
            run.start_controller(self.controllers[0])
        elif c.kind is CaseKind.KILL_EMULATOR:
            emulator = next(ch for ch in run.children if ch.name.startswith("emulator") and ch.returncode is None)
            emulator.stopping = True
            mark.t_inject = time.time()
            emulator.proc.kill()
            emulator.proc.wait()
            run.wait_s(OBSERVE_S)                  # the controller keeps its SYNC going
            run.start_emulator()
            run.wait_s(0.3)
        return False

    def _bad_waypoints(self, run, mark: Marks) -> None:
        host = run.host
        mark.t_inject = time.time()
        results = {}
        far = (self.home[0], self.home[1], self.home[2] + 0.5)
        results["outside the workspace"] = host.waypoint(far, segment_time_s=2.0, accel_time_s=0.5,
                                                         flags=WaypointFlag.LAST, expect_ok=False).name
        if self.rig == "hexapod":
            results["through a singularity (yaw 90 deg)"] = host.waypoint(
                self.home, rpy_rad=(0.0, 0.0, math.radians(90.0)), segment_time_s=4.0, accel_time_s=0.5,
                flags=WaypointFlag.LAST, expect_ok=False).name
        results["too fast (30 mm in 0.1 s)"] = host.waypoint(self.up, segment_time_s=0.1, accel_time_s=0.05,
                                                             flags=WaypointFlag.LAST, expect_ok=False).name
        try:                                       # the host's codec refuses a NaN: it never reaches the bus
            host.waypoint((math.nan, 0.0, self.home[2]), flags=WaypointFlag.LAST, expect_ok=False)
            results["NaN field"] = "SENT"
        except HostError as error:
            results["NaN field"] = "REFUSED by the host's codec (REJECTED: never on the bus)" \
                if "REJECTED" in str(error) else f"error: {error}"
        saved = host.waypoint_seq
        host.waypoint_seq = (saved + 5) % 256      # a gap in the sequence numbers
        results["sequence gap (+5)"] = host.waypoint(self.up, segment_time_s=2.0, accel_time_s=0.5,
                                                     flags=WaypointFlag.LAST, expect_ok=False).name
        host.waypoint_seq = saved
        run.wait_s(OBSERVE_S)
        mark.extra["acks"] = results

    # -- analysis --------------------------------------------------------------------------
    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        view = LogView(log, 1.0 / rate_hz, 6 if self.rig == "hexapod" else 1)
        baseline = next((m for m in self.marks if m.case.kind is CaseKind.BASELINE), None)
        run_dir = self._run.out if self._run is not None else None
        self.results = []
        for mark in self.marks:
            passed, measured, detail = JUDGES[mark.case.kind](view, mark, baseline, run_dir)
            recovered = mark.extra.get("recovered")
            unexplained = faults_in_windows(log, 1.0 / rate_hz, mark.extra.get("retried", ()))
            if unexplained:
                recovered = False
                mark.notes.append(f"a repeated recovery faulted with no machine stall before: {unexplained}")
            detail["notes"] = mark.notes
            self.results.append(CaseResult(mark.case.key, self.rig, mark.case.what, mark.case.bound, measured,
                                           bool(passed and recovered is not False), recovered, detail))
        checks = [Check(f"{r.key}: {r.what}", r.passed, r.measured + ("" if r.recovered is not False else
                                                                         "; RESET + ENABLE did not recover"),
                        r.bound) for r in self.results]
        table = ["| case | fault | bound | measured | recovered | pass |", "|---|---|---|---|---|---|"]
        table += [f"| {r.key} | {r.what} | {r.bound} | {r.measured} | {r.recovered} | "
                  f"{'yes' if r.passed else '**no**'} |" for r in self.results]
        metrics = {"cases": [r.as_dict() for r in self.results]}
        return Analysis(metrics, {}, checks, [], ["\n".join(table)])


def _pump_for(host, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        host.pump(min(0.01, max(end - time.monotonic(), 0.0)))


def encoder_node(leg: int, n_legs: int) -> int:
    """The stock layout's encoder of `leg` (protocol/devices/canopen-layout.toml)."""
    from protocol.canopen_layout import load_layout
    return next(d.node for d in load_layout(n_legs) if d.leg == leg and d.kind == "encoder")


def reset_node(host, node: int) -> None:
    """NMT RESET_NODE to `node`, as another master on the bus would send it."""
    box = Outbox("NMT")
    box.values[:] = (int(NmtCommand.RESET_NODE), node)
    host.send(box)
