"""`hydrapod hil faults`: the fault-injection matrix. Each case injects one fault into a
running system (emulator and controller as separate processes on the bus, this process the
host and recorder), measures the reaction from the recorded log and the emulator's ground
truth (EMU_TRUTH), and ends with RESET + ENABLE and a trajectory that must run normally.

A session is one emulator + controller pair on one rig and pacing, running its cases in
turn; the process cases (SIGKILL, SIGSTOP, a dead emulator) need realtime pacing and a
short valve SYNC watchdog (`VALVE_WATCHDOG_PERIODS`), the frame and plant cases run in lockstep (the same
cycles every run). Every case starts at rest at home with the controller READY, runs the
probe move (up 30 mm, back, 1.5 s each), injects its fault `INJECT_AT_S` into it, and
reads from the log:
- detection: cycles from the first affected SYNC to the controller's reaction (its first
  VALVE_CMD with M = 0, D = 0 for the e-stop), inclusive: a fault seen and acted on in the
  same cycle is 1; the reason from the next CTRL_STATUS. Persistent frame faults are
  judged on the cycles since the leg's last valid frame (what the configured counts count);
- excursion: the largest distance of the platform (the test bench's slide) from where it
  was at the injection, over `OBSERVE_S` after it (EMU_TRUTH, which keeps coming when the
  controller is dead: the emulator's plant runs on);
- transient faults: the largest distance from the same probe without a fault, judged on the
  legs (encoder strokes: the truth to one 0.125 mm count; cycles without the faulted leg's
  frame skipped) and reported for the platform. On the hexapod two no-fault probes differ
  by 1-2.5 mm horizontally (case 0b, measured in the same session): 1 mm of leg is 7-10 mm
  there, and the pose hunts as encoder counts flip, so the platform cannot carry a 1 mm
  criterion; its vertical axis repeats to 0.3 mm.
"""

from __future__ import annotations

import json
import math
import os
import signal
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from firmware_py.geometry import default_geometry
from firmware_py.supervisor import Command, Fault, State
from plant_emulator.emulator import FAULT_CODES, SYNC_TIMEOUT_EVENT
from protocol.values import (
    EMU_CLEAR_ALL,
    EMU_INJECT,
    FLAG_LAST,
    FLAG_START,
    KIND_HOST_CMD,
    KIND_WAYPOINT,
)

from .host import HostError
from .logdata import LogData
from .processes import ChildFailed
from .runner import RunOptions, run_scenario
from .scenario import Analysis, Check, Scenario

PROBE_RISE_M = 30e-3
PROBE_SEGMENT_S, PROBE_ACCEL_S = 1.5, 0.3
INJECT_AT_S = 0.5                 # into the probe's first segment (moving at ~20 mm/s)
OBSERVE_S = 1.0                   # excursion window after the injection
SETTLE_S = 2.0                    # at rest before the next case (the hexapod rings at ~1.5 Hz after a stop)
TRANSIENT_MAX_M = 1e-3            # transient faults: within 1 mm of the no-fault probe
HOLD_MOTION_MAX_M = 2e-3          # controller killed: the platform moves <= 2 mm afterwards
ENCODER_COUNT_M = 0.125e-3        # LEG_STATE's encoder (LXEP40, chapter 8.2.3)
STALL_S = 0.050                   # SIGSTOP
BABBLE_FRAMES_PER_SYNC = 15       # 1 Mbit/s, 135-bit frames: 7,400 frames/s = 14.8 per 2 ms
HOLD_WITHIN_PERIODS = 3           # case 1: every valve in FAULT_HOLD this long after the last command
# the valves' SYNC watchdog as configured for the matrix: half a period inside the bound, for
# the last command's lag behind its SYNC and a non-RT host's wake-up latency (at 3.0 the
# test bench's EMCY came 3.04 periods after the last command)
VALVE_WATCHDOG_PERIODS = 2.5
PLANT_FAULT_MAX_CYCLES = 250      # stuck encoder: FAULT within 0.5 s
SLOW_PLANT_FAULT_MAX_CYCLES = 500  # seized rod, lost supply: within 1 s (the motion window, see 5c)
TRY_LIMIT = 8                     # realtime: attempts of a case (or a recovery) a machine stall may spoil


@dataclass
class Case:
    key: str                      # "4b"
    what: str
    bound: str
    kind: str                     # how it is injected and judged (see Session.run_case)
    fault: str = ""               # EMU_CTRL fault name
    target: int = 1
    param: int = 0
    expect: tuple[str, ...] = ()  # acceptable controller fault codes (empty: no fault)
    max_cycles: int = 0           # detection bound
    rigs: tuple[str, ...] = ("hexapod", "testbench")


@dataclass
class Marks:
    """What the host knows about one case: times (epoch, as the log's) and cycles."""
    case: Case
    t_start: float = math.nan     # probe's first waypoint sent
    t_inject: float = math.nan
    t_end: float = math.nan
    notes: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)


def _emu(fault: str) -> int:
    return FAULT_CODES[fault]


LOCKSTEP_CASES = [
    Case("0", "no fault (the probe, for comparison)", "runs, no fault", "baseline"),
    Case("0b", "no fault, again (the comparison's floor)", "runs, no fault", "baseline"),
    Case("4a", "LEG_STATE of leg 1: 1 frame dropped", "no fault, <= 1 mm from no-fault run", "transient",
         "DROP", 1, 1),
    Case("4b", "LEG_STATE of leg 1: 10 consecutive drops", "SENSOR_TIMEOUT within 5 cycles", "persistent",
         "DROP", 1, 10, ("SENSOR_TIMEOUT",), 5),
    Case("4c", "LEG_STATE of leg 1: 100 consecutive drops", "SENSOR_TIMEOUT within 5 cycles", "persistent",
         "DROP", 1, 100, ("SENSOR_TIMEOUT",), 5),
    # E2E profile 1 with max delta 2 tolerates one lost frame between two received: after a
    # burst of n >= 2 the next good frame is a WRONG_SEQUENCE too, n + 1 rejections in a row
    Case("4d", "CRC corruption burst, 1 frame of leg 2", "no fault, <= 1 mm from no-fault run", "transient",
         "CORRUPT", 2, 1),
    Case("4e", "CRC corruption burst, 20 frames of leg 2", "E2E_ERROR within 3 cycles", "persistent",
         "CORRUPT", 2, 20, ("E2E_ERROR",), 3),
    Case("4f", "duplicated frames, leg 3 for 50 cycles", "rejected; no fault, <= 1 mm", "transient",
         "DUPLICATE", 3, 50),
    Case("4g", "out-of-order counters: one swapped pair, leg 3", "rejected; no fault, <= 1 mm", "transient",
         "REORDER", 3, 2),
    # swapped every other cycle: after the first swap the receiver re-synchronises to the late
    # frame's counter and every later frame is a WRONG_SEQUENCE, as profile 1 demands
    Case("4g2", "out-of-order counters, leg 3 for 50 cycles", "SENSOR_TIMEOUT or E2E_ERROR within 5 cycles",
         "persistent", "REORDER", 3, 50, ("SENSOR_TIMEOUT", "E2E_ERROR"), 5),
    Case("4h", "repeated counter (stale frame), leg 4 for 1 cycle", "rejected; no fault, <= 1 mm", "transient",
         "REPEAT", 4, 1),
    Case("4i", "repeated counter (stale frame), leg 4 for 50 cycles", "E2E_ERROR within 3 cycles", "persistent",
         "REPEAT", 4, 50, ("E2E_ERROR",), 3),
    Case("3b", "sensor node of leg 3 silent", "SENSOR_TIMEOUT within 5 cycles, held, no NaN", "persistent",
         "SILENT", 3, 0, ("SENSOR_TIMEOUT",), 5),
    # hexapod: the IMU disagrees with the encoders' attitude (ATTITUDE_MISMATCH); the test
    # bench has no IMU: the motion window or the tracking limit
    Case("5a", "stuck encoder, leg 2", "FAULT within 0.5 s", "plant", "STUCK", 2, 0,
         ("ATTITUDE_MISMATCH", "MOTION_PLAUSIBILITY", "TRACKING_ERROR"), PLANT_FAULT_MAX_CYCLES),
    Case("5b", "out-of-range force, leg 4", "FORCE_LIMIT within 1 cycle", "plant", "OUT_OF_RANGE", 4, 0,
         ("FORCE_LIMIT",), 1),
    # a seized rod and a lost supply are seen by the motion window (30 % input for 0.2 s
    # without 0.5 mm of travel) once the PI has wound the valve up to 30 %: ~0.5 s, then
    # 0.2 s of window. A 10 % window catches them sooner but trips the hexapod's pm-circle
    # (model-based legs hold their load at > 10 % input without moving)
    Case("5c", "leg jam (rod seized), leg 1", "FAULT within 1 s", "plant", "LEG_JAM", 1, 0,
         ("MOTION_PLAUSIBILITY", "TRACKING_ERROR", "VELOCITY_LIMIT"), SLOW_PLANT_FAULT_MAX_CYCLES),
    Case("5d", "loss of supply pressure", "FAULT within 1 s", "plant", "SUPPLY_LOSS", 0, 0,
         ("MOTION_PLAUSIBILITY", "TRACKING_ERROR", "VELOCITY_LIMIT"), SLOW_PLANT_FAULT_MAX_CYCLES),
    Case("6", "e-stop from the host mid-trajectory", "valves disabled in the cycle of the command", "estop",
         expect=("ESTOP",), max_cycles=1),
    Case("7", "bad waypoints: outside, singular, too fast, NaN, sequence gap", "each rejected with its reason, "
         "zero motion", "waypoints"),
]
REALTIME_CASES = [
    Case("0", "no fault, realtime (the period reference for the babble case)", "runs, no fault", "baseline"),
    Case("8", f"babbling node: {BABBLE_FRAMES_PER_SYNC} frames of id 0x601 per SYNC (the bus's capacity)",
         "period kept (jitter reported); cyclic frames through or FAULT", "babble", "BABBLE", 0,
         BABBLE_FRAMES_PER_SYNC),
    Case("2", "controller stalled: SIGSTOP 50 ms, SIGCONT", "valves FAULT_HOLD; controller FAULT, no motion "
         "without reset", "stall", expect=("OVERRUN", "VALVE_FAULT")),
    Case("1", "controller killed (SIGKILL) mid-trajectory", "every valve FAULT_HOLD <= 3 SYNC periods after "
         "the last command, EMCY; platform <= 2 mm after", "kill"),
    Case("3a", "emulator killed", "controller FAULT within 5 cycles, valves commanded to hold, no NaN",
         "kill_emulator", expect=("SENSOR_TIMEOUT",), max_cycles=5),
]


@dataclass
class CaseResult:
    key: str
    rig: str
    what: str
    bound: str
    measured: str
    passed: bool
    recovered: bool | None            # case 9: RESET + ENABLE -> READY and a trajectory ran
    detail: dict

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class Session(Scenario):
    """One emulator + controller pair running a list of cases."""

    def __init__(self, rig: str, pacing: str, cases: list[Case]):
        self.rig, self.pacing, self.pacings = rig, pacing, (pacing,)
        n_legs = 6 if rig == "hexapod" else 1
        # the test bench has one leg: a case aimed at leg 2-6 hits its only one
        self.cases = [c if c.target <= n_legs else replace(c, target=1, what=c.what.replace(f"leg {c.target}", "leg 1"))
                      for c in cases if rig in c.rigs]
        self.name = f"faults-{rig}-{pacing}"
        self.title = f"fault-injection matrix, {rig}, {pacing}"
        self.chapter = "reliability (DESIGN.md Protocol, Supervisor)"
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
            if run.host.state is not State.READY or case.kind in ("kill", "kill_emulator"):
                self._recover(run, mark)
            else:                                  # no fault: nothing to recover from
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

        Realtime: a machine stall during the recovery trips the stall watchdog (OVERRUN) as it
        must; that recovery is repeated (noted), up to TRY_LIMIT times. Any other fault fails it.
        """
        host = run.host
        host.emulator(EMU_CLEAR_ALL)
        run.wait_s(0.1)
        for attempt in range(1, TRY_LIMIT + 1):
            ok, error = self._recover_once(run)
            run.await_fault_shown(error)
            stalled = (not ok and run.pacing == "realtime" and host.state is State.FAULT
                       and host.fault_code == Fault.OVERRUN)
            if error is not None:
                mark.notes.append(f"recovery: {error}")
            if not stalled or attempt == TRY_LIMIT:
                break
            mark.notes.append(f"recovery attempt {attempt}: a machine stall faulted OVERRUN; repeated")
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
                          flags=FLAG_LAST | FLAG_START)
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
                      flags=FLAG_LAST | FLAG_START)
        mark.extra["probe_seq"] = (host.waypoint_seq - 1) % 256
        host.waypoint(self.home, segment_time_s=PROBE_SEGMENT_S, accel_time_s=PROBE_ACCEL_S,
                      flags=FLAG_LAST | FLAG_START)
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
        run.host.emulator(EMU_INJECT, target=c.target, fault=_emu(c.fault), param=c.param)

    def run_case(self, run, mark: Marks) -> bool:
        """Inject and observe; True when a machine stall spoiled it before the injection."""
        c, host = mark.case, run.host
        if c.kind == "waypoints":
            self._bad_waypoints(run, mark)
            return False
        self._probe(run, mark)
        if host.state is State.FAULT:
            return run.pacing == "realtime"
        if c.kind == "baseline":
            self._finish_probe(run)
            # realtime: nothing was injected, so an OVERRUN is the machine's stall (3 periods)
            return run.pacing == "realtime" and host.state is State.FAULT
        elif c.kind in ("transient", "persistent", "plant"):
            self._inject(run, mark)
            self._finish_probe(run)
        elif c.kind == "estop":
            mark.t_inject = time.time()
            host.command(Command.ESTOP)
            run.wait_s(OBSERVE_S)
        elif c.kind == "babble":
            self._inject(run, mark)
            self._finish_probe(run)
        elif c.kind == "stall":
            child = run.controller
            mark.t_inject = time.time()
            os.kill(child.proc.pid, signal.SIGSTOP)
            _pump_for(host, STALL_S)
            os.kill(child.proc.pid, signal.SIGCONT)
            mark.extra["t_cont"] = time.time()
            host.wait_until(lambda: host.state is State.FAULT, run.cycles(1.0), what=None)
            run.wait_s(OBSERVE_S)                  # held: no motion without a reset
        elif c.kind == "kill":
            child = run.controller
            child.stopping = True
            mark.t_inject = time.time()
            child.proc.kill()
            child.proc.wait()
            _pump_for(host, OBSERVE_S)             # the plant runs on; EMCY and EMU_TRUTH recorded
            run.controller = None
            run.start_controller(self.controllers[0])
        elif c.kind == "kill_emulator":
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
                                                         flags=FLAG_LAST, expect_ok=False).name
        if self.rig == "hexapod":
            results["through a singularity (yaw 90 deg)"] = host.waypoint(
                self.home, rpy_rad=(0.0, 0.0, math.radians(90.0)), segment_time_s=4.0, accel_time_s=0.5,
                flags=FLAG_LAST, expect_ok=False).name
        results["too fast (30 mm in 0.1 s)"] = host.waypoint(self.up, segment_time_s=0.1, accel_time_s=0.05,
                                                             flags=FLAG_LAST, expect_ok=False).name
        try:                                       # the host's codec refuses a NaN: it never reaches the bus
            host.waypoint((math.nan, 0.0, self.home[2]), flags=FLAG_LAST, expect_ok=False)
            results["NaN field"] = "SENT"
        except HostError as error:
            results["NaN field"] = "REFUSED by the host's codec (REJECTED: never on the bus)" \
                if "REJECTED" in str(error) else f"error: {error}"
        saved = host.waypoint_seq
        host.waypoint_seq = (saved + 5) % 256      # a gap in the sequence numbers
        results["sequence gap (+5)"] = host.waypoint(self.up, segment_time_s=2.0, accel_time_s=0.5,
                                                     flags=FLAG_LAST, expect_ok=False).name
        host.waypoint_seq = saved
        run.wait_s(OBSERVE_S)
        mark.extra["acks"] = results

    # -- analysis --------------------------------------------------------------------------
    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        view = LogView(log, 1.0 / rate_hz, 6 if self.rig == "hexapod" else 1)
        baseline = next((m for m in self.marks if m.case.kind == "baseline"), None)
        self.results = []
        for mark in self.marks:
            measure = getattr(self, f"_measure_{mark.case.kind}", self._measure_fault)
            passed, measured, detail = measure(view, mark, baseline)
            recovered = mark.extra.get("recovered")
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

    def _measure_baseline(self, view, mark, baseline):
        faults = view.faults_between(mark.t_start, mark.t_end)
        ran = not math.isnan(mark.t_start) and "host_error" not in mark.extra
        measured = f"faults {faults or 'none'}" + ("" if ran else "; the probe did not run")
        legs = platform = None
        if baseline is not None and mark is not baseline:    # the same probe again: the comparison's floor
            legs, platform = view.deviation_from(mark, baseline)
            measured += f"; legs {_mm(legs)}, platform {_mm(platform)} from the first no-fault run (from {INJECT_AT_S:g} s into the probe)"
        return ran and not faults, measured, {"faults": faults, "leg_deviation_m": legs,
                                              "platform_deviation_m": platform}

    def _measure_transient(self, view, mark, baseline):
        faults = view.faults_between(mark.t_start, mark.t_end)
        legs, platform = view.deviation_from(mark, baseline)
        rejected = view.rejected_between(mark.case.target, mark.t_inject, mark.t_end)
        passed = not faults and legs is not None and legs <= TRANSIENT_MAX_M + 1e-9   # inclusive, at float resolution
        measured = (f"no fault; legs {_mm(legs)} (platform {_mm(platform)}) from the no-fault run after the injection; leg "
                    f"{mark.case.target}: {rejected['missing']} cycles without its frame, "
                    f"{rejected['rejected']} frames rejected" if not faults else f"FAULT {faults}")
        return passed, measured, {"faults": faults, "leg_deviation_m": legs, "platform_deviation_m": platform,
                                  **rejected}

    def _measure_fault(self, view, mark, baseline):
        """Persistent and plant faults: the reason, the cycles to the reaction, the excursion."""
        c = mark.case
        k0 = view.first_affected_cycle(mark, c)
        reaction = view.reaction_cycle(k0, "CW_M")
        code = view.fault_code_after(k0)
        cycles = None if reaction is None or k0 is None else reaction - k0 + 1
        judged = cycles
        excursion = view.excursion(mark.t_inject, OBSERVE_S)
        held = view.held_after(reaction)
        measured = f"{code} after {cycles} cycles"
        if c.kind == "persistent" and reaction is not None:
            # the configured counts are of cycles in a row without a valid frame: a frame
            # accepted in between (a reordered pair's first) starts them again
            last = view.last_valid_frame_cycle(c.target, reaction)
            judged = reaction - last if last is not None and last >= (k0 or 0) else cycles
            measured += f" ({judged} since its last valid frame)"
        passed = (code in c.expect and judged is not None and judged <= c.max_cycles and held)
        measured += f"; excursion {_mm(excursion)}; VALVE_CMD every cycle after it with M = 0: {held}"
        if c.kind == "persistent":
            rejected = view.rejected_between(c.target, mark.t_inject, mark.t_end)
            measured += f"; {rejected['rejected']} frames rejected"
        return passed, measured, {"code": code, "cycles": cycles, "excursion_m": excursion, "held": held}

    def _measure_estop(self, view, mark, baseline):
        ack_cycle = view.ack_cycle(Command.ESTOP, mark.t_inject)
        disabled = view.reaction_cycle(ack_cycle, "CW_D")
        same = ack_cycle is not None and disabled == ack_cycle
        valve_off = view.valve_state_from(disabled, 1)
        excursion = view.excursion(mark.t_inject, OBSERVE_S)
        measured = (f"D = 0 in the ESTOP's cycle: {same} (ack cycle {ack_cycle}, D = 0 cycle {disabled}); "
                    f"valves DISABLED {valve_off} cycles later; excursion {_mm(excursion)}")
        return same and valve_off is not None and valve_off <= 1, measured, {
            "ack_cycle": ack_cycle, "disabled_cycle": disabled, "excursion_m": excursion}

    def _measure_waypoints(self, view, mark, baseline):
        acks = mark.extra.get("acks", {})
        expected = {"outside the workspace": ("OUTSIDE_WORKSPACE",),
                    "through a singularity (yaw 90 deg)": ("SINGULAR", "OUTSIDE_WORKSPACE"),
                    "too fast (30 mm in 0.1 s)": ("TOO_FAST",), "sequence gap (+5)": ("SEQUENCE_GAP",)}
        ok = all(acks.get(k) in allowed for k, allowed in expected.items()
                 if k in acks or not k.startswith("through"))          # no singularity on the bench
        ok = ok and acks.get("NaN field", "").startswith("REFUSED")
        # zero motion: never RUNNING, and no leg's encoder moves by more than the one count its
        # hold hunts over (a position loop cannot see less). The platform's own range (truth)
        # is reported beside its range holding at rest in as long a window just before: both
        # hunt (0.1-0.3 mm on the hexapod, one count of a slender leg amplified)
        span = mark.t_end - mark.t_inject
        k0, k1 = view.cycle_at(mark.t_inject), view.cycle_at(mark.t_end)
        legs = view.leg_range(k0, k1)
        motion = view.truth_range(mark.t_inject, mark.t_end)
        floor = view.truth_range(mark.t_inject - span, mark.t_inject)
        states = view.states_between(mark.t_inject, mark.t_end)
        still = "RUNNING" not in states and legs is not None and legs <= ENCODER_COUNT_M * 1.001
        measured = "; ".join(f"{k}: {v}" for k, v in acks.items()) + \
            (f"; states {states}; legs moved "
             f"{'n/a' if legs is None else f'{legs / ENCODER_COUNT_M:.0f}'} encoder count(s) at most (bound 1); "
             f"platform range {_mm(motion)} (holding at rest before: {_mm(floor)})")
        return ok and still, measured, {"acks": acks, "leg_range_m": legs, "platform_range_m": motion,
                                        "hold_platform_range_m": floor, "states": states}

    def _measure_babble(self, view, mark, baseline):
        faults = view.faults_between(mark.t_start, mark.t_end)
        during = view.period_error_us(mark.t_inject, mark.t_end)
        before = view.period_error_us(baseline.t_start, baseline.t_end) if baseline else {}
        missing = sum(view.rejected_between(leg, mark.t_inject, mark.t_end)["missing"]
                      for leg in range(1, view.n_legs + 1))
        unknown = view.log.unknown_frames          # the session's: only this case babbles
        through = missing == 0 and not faults
        passed = through or bool(faults)
        measured = (f"{unknown} babble frames; LEG_STATE missing {missing} leg-cycles; faults {faults or 'none'}; "
                    f"period error p99 {during.get('p99')} us (max {during.get('max')}) vs "
                    f"{before.get('p99')} us (max {before.get('max')}) without")
        return passed, measured, {"faults": faults, "missing": missing, "unknown_frames": unknown,
                                  "period_error_us": during, "period_error_us_without": before}

    def _measure_stall(self, view, mark, baseline):
        emcy = view.emergencies_after(mark.t_inject, mark.t_inject + 1.0)
        legs = sorted({leg for leg, _, _ in emcy})
        code = view.fault_code_after(view.cycle_at(mark.t_inject))
        k_cont = view.cycle_at(mark.extra.get("t_cont", mark.t_inject))
        reaction = view.reaction_cycle(k_cont, "CW_M")
        held = view.held_after(reaction)
        resumed_early = view.resumed_without_reset(mark.t_inject, mark.t_end)
        excursion = view.excursion(mark.t_inject, OBSERVE_S)
        passed = (legs == list(range(1, view.n_legs + 1)) and code in mark.case.expect and held
                  and not resumed_early)
        measured = (f"EMCY from legs {legs}; controller {code}; held after: {held}; "
                    f"resumed without reset: {resumed_early}; excursion {_mm(excursion)}")
        return passed, measured, {"emcy_legs": legs, "code": code, "excursion_m": excursion}

    def _measure_kill(self, view, mark, baseline):
        last_cmd = view.last_command_before(mark.t_inject + 0.5)
        # SYNC is part of the command stream (a VALVE_CMD takes effect at the next SYNC): a
        # controller killed between its SYNC and its VALVE_CMD (the host acts on SYNC, so
        # often) last commanded with that SYNC, a period after its last VALVE_CMD frame
        last_sync = view.last_sync_before(mark.t_inject + 0.5)
        applied = None if last_cmd is None else max(last_cmd, last_sync or last_cmd)
        emcy = view.emergencies_after(mark.t_inject - 0.01, mark.t_inject + 1.0)
        legs = sorted({leg for leg, _, _ in emcy})
        latest = max((t for _, t, _ in emcy), default=math.nan)
        periods = (latest - last_cmd) / view.period_s if last_cmd is not None else math.nan
        from_applied = (latest - applied) / view.period_s if applied is not None else math.nan
        # the emulated nodes' SYNC watchdog is the emulator process's clock, not a hardware
        # timer started by the SYNC on the bus: how far behind it ran for this trip (the last
        # SYNC's wait in its socket plus its wake-up for the trip, its own measurement) is not
        # the node's
        late_ms = self._emulator_trip_late_ms(mark.t_inject - 0.01, mark.t_inject + 1.0)
        node_periods = from_applied - (late_ms or 0.0) * 1e-3 / view.period_s
        excursion = view.excursion(mark.t_inject, OBSERVE_S)
        passed = (legs == list(range(1, view.n_legs + 1)) and node_periods <= HOLD_WITHIN_PERIODS
                  and excursion is not None and excursion <= HOLD_MOTION_MAX_M)
        late = "" if late_ms is None else f", the emulator process {late_ms:.2f} ms behind it"
        measured = (f"EMCY (SYNC timeout) from legs {legs}, the last {periods:.2f} periods after the last "
                    f"VALVE_CMD frame, {from_applied:.2f} after its last SYNC or VALVE_CMD ({node_periods:.2f} on "
                    f"the nodes' clock{late}); platform moved {_mm(excursion)} in {OBSERVE_S:g} s after")
        return passed, measured, {"emcy_legs": legs, "periods_after_last_command": periods,
                                  "periods_after_last_sync_or_command": from_applied, "emulator_trip_late_ms": late_ms,
                                  "node_periods": node_periods, "excursion_m": excursion}

    def _emulator_trip_late_ms(self, t0: float, t1: float) -> float | None:
        """The emulator's own record of its SYNC-watchdog trips in [t0, t1] (None: no run)."""
        run = self._run
        if run is None:
            return None
        late = []
        for path in run.out.glob("emulator*.stderr.log"):     # a killed emulator leaves no summary
            for line in path.read_text(errors="replace").splitlines():
                if line.startswith(SYNC_TIMEOUT_EVENT):
                    try:
                        trip = json.loads(line[len(SYNC_TIMEOUT_EVENT):])
                    except ValueError:
                        continue
                    if t0 <= trip["t_epoch_s"] <= t1:
                        late.append(trip["late_ms"])
        return max(late) if late else None

    def _measure_kill_emulator(self, view, mark, baseline):
        k0 = view.cycle_at(mark.t_inject)
        last_frame = view.last_leg_state_cycle_before(mark.t_inject + 0.5)
        reaction = view.reaction_cycle(k0, "CW_M")
        code = view.fault_code_after(k0)
        cycles = None if reaction is None or last_frame is None else reaction - last_frame
        held = view.held_after(reaction, until=mark.t_inject + OBSERVE_S)
        passed = code in mark.case.expect and cycles is not None and cycles <= mark.case.max_cycles and held
        measured = (f"{code} {cycles} cycles after the last LEG_STATE; VALVE_CMD (finite, M = 0) every cycle "
                    f"after: {held}")
        return passed, measured, {"code": code, "cycles": cycles, "held": held}


def _pump_for(host, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        host.pump(min(0.01, max(end - time.monotonic(), 0.0)))


def _mm(value) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{value * 1e3:.2f} mm"


class LogView:
    """The recorded log, read for the matrix's measurements (times are the log's)."""

    def __init__(self, log: LogData, period_s: float, n_legs: int):
        self.log, self.period_s, self.n_legs = log, period_s, n_legs
        self.sync_t = log.sync_time_s
        truth = log.get("EMU_TRUTH")
        self.truth_t = truth.time_s
        self.truth = np.column_stack([truth["X"], truth["Y"], truth["Z"]]) if n_legs == 6 else truth["Z"][:, None]
        self.status = log.get("CTRL_STATUS")
        self.cmds = [log.get(f"VALVE_CMD_{leg}") for leg in range(1, n_legs + 1)]
        self.legs = log.leg_positions(n_legs)          # (cycles, legs), NaN where a frame is missing

    def cycle_at(self, t: float) -> int | None:
        """The first cycle whose SYNC is at or after `t`."""
        valid = np.isfinite(self.sync_t)
        k = np.flatnonzero(valid & (self.sync_t >= t))
        return int(k[0]) if len(k) else None

    def faults_between(self, t0: float, t1: float) -> list[str]:
        s = self.status
        ok = (s.time_s >= t0) & (s.time_s <= t1) & (s["FAULT_CODE"] != 0)
        return sorted({Fault(int(c)).name for c in s["FAULT_CODE"][ok]})

    def states_between(self, t0: float, t1: float) -> list[str]:
        s = self.status
        ok = (s.time_s >= t0) & (s.time_s <= t1)
        return sorted({State(int(c)).name for c in s["STATE"][ok]})

    def fault_code_after(self, k0: int | None) -> str | None:
        if k0 is None:
            return None
        s = self.status
        idx = np.flatnonzero((s.cycle >= k0) & (s["FAULT_CODE"] != 0))
        return Fault(int(s["FAULT_CODE"][idx[0]])).name if len(idx) else None

    def reaction_cycle(self, k0: int | None, bit: str) -> int | None:
        """The first cycle >= k0 in which the controller wrote `bit` = 0 to a valve."""
        if k0 is None:
            return None
        first = [c.cycle[np.flatnonzero((c.cycle >= k0) & (c[bit] == 0))] for c in self.cmds]
        first = [int(f[0]) for f in first if len(f)]
        return min(first) if first else None

    def held_after(self, k: int | None, until: float | None = None) -> bool:
        """From cycle k on, every cycle has every leg's VALVE_CMD with M = 0 (until a RESET
        or `until`): the controller held and never resumed motion by itself."""
        if k is None:
            return False
        end = self.log.n_cycles if until is None else (self.cycle_at(until) or self.log.n_cycles)
        reset = self._first_command_cycle(Command.RESET, k)
        if reset is not None:
            end = min(end, reset)
        for c in self.cmds:
            sel = (c.cycle >= k) & (c.cycle < end)
            if np.any(c["CW_M"][sel] != 0) or len(np.unique(c.cycle[sel])) < (end - k) * 0.98:
                return False
        return True

    def _first_command_cycle(self, command: Command, k0: int) -> int | None:
        for e in self.log.events_named("HOST_CMD"):
            if e.cycle >= k0 and int(e.values["COMMAND"]) == command:
                return e.cycle
        return None

    def resumed_without_reset(self, t0: float, t1: float) -> bool:
        k0 = self.cycle_at(t0)
        if k0 is None:
            return False
        reset = self._first_command_cycle(Command.RESET, k0) or self.log.n_cycles
        fault = self.reaction_cycle(k0, "CW_M")
        if fault is None:
            return True
        return any(np.any((c.cycle > fault) & (c.cycle < reset) & (c["CW_M"] != 0)) for c in self.cmds)

    def ack_cycle(self, command: Command, t0: float) -> int | None:
        seqs = {int(e.values["SEQ"]) for e in self.log.events_named("HOST_CMD")
                if e.time_s >= t0 - 0.01 and int(e.values["COMMAND"]) == command}
        for e in self.log.events_named("CTRL_ACK"):
            if e.time_s >= t0 - 0.01 and int(e.values["KIND"]) == KIND_HOST_CMD and int(e.values["SEQ"]) in seqs:
                return e.cycle
        return None

    def valve_state_from(self, k: int | None, state: int) -> int | None:
        """Cycles after k until every leg reports valve `state` in LEG_STATE."""
        if k is None:
            return None
        latest = 0
        for leg in range(1, self.n_legs + 1):
            s = self.log.get(f"LEG_STATE_{leg}")
            idx = np.flatnonzero((s.cycle >= k) & (s["VALVE_STATE"] == state))
            if not len(idx):
                return None
            latest = max(latest, int(s.cycle[idx[0]]) - k)
        return latest

    def last_valid_frame_cycle(self, leg: int, k: int) -> int | None:
        """The last cycle up to k in which leg's LEG_STATE was accepted."""
        s = self.log.get(f"LEG_STATE_{leg}")
        idx = np.flatnonzero(s.cycle <= k)
        return int(s.cycle[idx[-1]]) if len(idx) else None

    def first_affected_cycle(self, mark: Marks, case: Case) -> int | None:
        """Frame faults: the first cycle from the injection without an OK LEG_STATE of the
        target; plant faults: the first SYNC after the EMU_CTRL."""
        k0 = self.cycle_at(mark.t_inject)
        if k0 is None or case.kind == "plant":
            return k0
        s = self.log.get(f"LEG_STATE_{case.target}")
        present = set(s.cycle[s.cycle >= k0].tolist())
        for k in range(k0, min(k0 + 50, self.log.n_cycles)):
            if k not in present:
                return k
        return None

    def rejected_between(self, leg: int, t0: float, t1: float) -> dict:
        k0, k1 = self.cycle_at(t0), self.cycle_at(t1) or self.log.n_cycles
        if k0 is None:
            return {"missing": 0, "rejected": 0}
        s = self.log.get(f"LEG_STATE_{leg}")
        present = np.unique(s.cycle[(s.cycle >= k0) & (s.cycle < k1)])
        rejected = self.log.rejected.get(f"LEG_STATE_{leg}", np.zeros(0, dtype=np.int64))
        return {"missing": int((k1 - k0) - len(present)),
                "rejected": int(np.count_nonzero((rejected >= k0) & (rejected < k1)))}

    def deviation_from(self, mark: Marks, baseline: Marks | None) -> tuple[float | None, float | None]:
        """Largest difference of this probe from the baseline's after the injection (the
        probes aligned at the commit of their first waypoint), to 0.5 s after the probe:
        (largest leg stroke difference, largest platform distance). What comes before the
        injection cannot be the fault's: two no-fault probes differ there by the start from
        rest (the test bench's stiction: a breakaway 75 ms earlier or later, 1.1 mm)."""
        if baseline is None:
            return None, None
        ka, kb = self.waypoint_ack_cycle(mark), self.waypoint_ack_cycle(baseline)
        if ka is None or kb is None:
            return None, None
        k_inject = self.cycle_at(mark.t_inject) if not math.isnan(mark.t_inject) else None
        skip = k_inject - ka if k_inject is not None else int(round(INJECT_AT_S / self.period_s))
        span = 2 * PROBE_SEGMENT_S + 0.5 - skip * self.period_s
        a, b = self._truth_window(ka + skip, span), self._truth_window(kb + skip, span)
        platform = None if a is None or b is None else float(np.max(np.linalg.norm(a - b, axis=1)))
        la, lb = self._legs_window(ka + skip, span), self._legs_window(kb + skip, span)
        legs = None if la is None or lb is None else float(np.nanmax(np.abs(la - lb)))
        return legs, platform

    def _legs_window(self, k0: int | None, span: float):
        n = int(round(span / self.period_s))
        if k0 is None or k0 + n > len(self.legs):
            return None
        return self.legs[k0:k0 + n]

    def waypoint_ack_cycle(self, mark: Marks) -> int | None:
        """The cycle the probe's first waypoint was committed (its CTRL_ACK)."""
        seq = mark.extra.get("probe_seq")
        for e in self.log.events_named("CTRL_ACK"):
            if (e.time_s >= mark.t_start and int(e.values["KIND"]) == KIND_WAYPOINT
                    and int(e.values["SEQ"]) == seq):
                return e.cycle
        return None

    def _truth_window(self, k0: int | None, span: float):
        """Truth per cycle from cycle k0 on."""
        if k0 is None:
            return None
        truth = self.log.get("EMU_TRUTH")
        n = int(round(span / self.period_s))
        rows = np.full((n, self.truth.shape[1]), np.nan)
        sel = (truth.cycle >= k0) & (truth.cycle < k0 + n)
        rows[truth.cycle[sel] - k0] = self.truth[sel]
        keep = np.all(np.isfinite(rows), axis=1)
        return rows if keep.mean() > 0.9 else None

    def leg_range(self, k0: int | None, k1: int | None) -> float | None:
        """The largest range (max - min) of any leg's encoder over cycles [k0, k1)."""
        if k0 is None or k1 is None or k1 <= k0:
            return None
        window = self.legs[k0:k1]
        if not np.isfinite(window).any():
            return None
        return float(np.nanmax(np.nanmax(window, axis=0) - np.nanmin(window, axis=0)))

    def truth_range(self, t0: float, t1: float) -> float | None:
        """The size of the box the platform (or slide) stayed in between t0 and t1 (truth)."""
        sel = (self.truth_t >= t0) & (self.truth_t <= t1)
        if not sel.any():
            return None
        return float(np.linalg.norm(self.truth[sel].max(axis=0) - self.truth[sel].min(axis=0)))

    def excursion(self, t0: float, span: float) -> float | None:
        sel = (self.truth_t >= t0) & (self.truth_t <= t0 + span)
        before = np.flatnonzero(self.truth_t < t0)
        if not sel.any() or not len(before):
            return None
        start = self.truth[before[-1]]
        return float(np.max(np.linalg.norm(self.truth[sel] - start, axis=1)))

    def emergencies_after(self, t0: float, t1: float) -> list[tuple[int, float, int]]:
        out = []
        for e in self.log.events:
            if e.name.startswith("EMCY_") and t0 <= e.time_s <= t1 and e.values["ERROR_CODE"] != 0:
                out.append((int(e.name.split("_")[1]), e.time_s, int(e.values["DETAIL"])))
        return out

    def last_sync_before(self, t: float) -> float | None:
        earlier = self.sync_t[np.isfinite(self.sync_t) & (self.sync_t <= t)]
        return float(earlier.max()) if len(earlier) else None

    def last_command_before(self, t: float) -> float | None:
        times = [c.time_s[c.time_s <= t] for c in self.cmds]
        times = [float(x[-1]) for x in times if len(x)]
        return max(times) if times else None

    def last_leg_state_cycle_before(self, t: float) -> int | None:
        last = None
        for leg in range(1, self.n_legs + 1):
            s = self.log.get(f"LEG_STATE_{leg}")
            c = s.cycle[s.time_s <= t]
            if len(c):
                last = max(last or 0, int(c[-1]))
        return last

    def period_error_us(self, t0: float, t1: float) -> dict:
        s = self.status
        sel = (s.time_s >= t0) & (s.time_s <= t1)
        values = s["PERIOD_ERROR_MAX"][sel] * 1e6
        if not len(values):
            return {}
        return {"p50": round(float(np.percentile(values, 50)), 1), "p99": round(float(np.percentile(values, 99)), 1),
                "max": round(float(values.max()), 1)}


# -- the matrix ---------------------------------------------------------------------------
def sessions(short: bool) -> list[Session]:
    """Full: every case on both rigs. Short (make test): every case on the hexapod (~2 min;
    the suite's 20-minute budget has no room for the test bench's two sessions too)."""
    out = [Session("hexapod", "lockstep", LOCKSTEP_CASES), Session("hexapod", "realtime", REALTIME_CASES)]
    if not short:
        out += [Session("testbench", "lockstep", LOCKSTEP_CASES), Session("testbench", "realtime", REALTIME_CASES)]
    return out


def run_matrix(out: Path, short: bool, bus: str | None = None, start_timeout_s: float = 90.0) -> dict:
    results, runs = [], []
    for session in sessions(short):
        options = RunOptions(out_dir=out / session.name, bus=bus, short=short, start_timeout_s=start_timeout_s,
                             valve_watchdog_periods=VALVE_WATCHDOG_PERIODS if session.pacing == "realtime" else None)
        doc = run_scenario(session, options)
        runs.append({"session": session.name, "passed": doc["passed"], "failure": doc.get("failure"),
                     "e2e_errors": doc["e2e_errors"], "wall_time_s": doc.get("wall_time_s")})
        results += doc["metrics"].get("cases", [])
        expected = {c.key for c in session.cases}
        missing = expected - {r["key"] for r in doc["metrics"].get("cases", [])}
        for key in sorted(missing):
            results.append({"key": key, "rig": session.rig, "what": "(not run)", "bound": "", "passed": False,
                            "measured": f"the session ended early: {doc.get('failure')}", "recovered": None,
                            "detail": {}})
    passed = bool(results) and all(r["passed"] for r in results) and not any(r["failure"] for r in runs)
    doc = {"passed": passed, "cases": results, "sessions": runs}
    (out / "faults.json").write_text(json.dumps(doc, indent=1, default=str))
    (out / "faults.md").write_text(format_matrix(doc))
    return doc


def format_matrix(doc: dict) -> str:
    lines = ["# Fault-injection matrix", "", f"Result: **{'PASSED' if doc['passed'] else 'FAILED'}**", "",
             "| case | rig | fault | bound | measured | recovered (9) | pass |", "|---|---|---|---|---|---|---|"]
    for r in doc["cases"]:
        lines.append(f"| {r['key']} | {r['rig']} | {r['what']} | {r['bound']} | {r['measured']} | "
                     f"{r['recovered']} | {'yes' if r['passed'] else '**no**'} |")
    noted = [r for r in doc["cases"] if r["detail"].get("notes")]
    if noted:     # spoiled attempts and repeated recoveries (machine stalls), in the open
        lines += ["", "Notes:"] + [f"- {r['key']} ({r['rig']}): " + " | ".join(r["detail"]["notes"]) for r in noted]
    lines += ["", "| session | passed | wall s | E2E errors | failure |", "|---|---|---|---|---|"]
    for s in doc["sessions"]:
        lines.append(f"| {s['session']} | {s['passed']} | {s['wall_time_s']} | {s['e2e_errors']} | "
                     f"{(s['failure'] or '').splitlines()[0] if s['failure'] else ''} |")
    return "\n".join(lines) + "\n"


def format_terminal(doc: dict) -> str:
    lines = [f"faults: {'PASSED' if doc['passed'] else 'FAILED'}"]
    for r in doc["cases"]:
        lines.append(f"  [{'ok' if r['passed'] else 'FAIL'}] {r['key']:>3} {r['rig']:<9} {r['what']}: {r['measured']}"
                     f" (bound: {r['bound']}; recovered: {r['recovered']})")
    for s in doc["sessions"]:
        if s["failure"]:
            lines.append(f"  session {s['session']} failed: {s['failure']}")
    return "\n".join(lines)


