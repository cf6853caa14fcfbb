"""`hydrapod hil soak --minutes M`: the hexapod in realtime pacing moves through a loop of
poses for M minutes while the host injects random frame faults.

Most faults are transient (one dropped, corrupted, stale or swapped LEG_STATE, a run of
duplicates): the controller must reject the bad frames and carry on without a fault. One in
PERSISTENT_EVERY is persistent (10 drops, a 20-frame CRC burst): the controller must fault
with its code within its configured count, and RESET + ENABLE must bring it back to READY
and moving. Every injection is an EMU_CTRL frame in the log, so the analysis needs the log
alone (`hil analyze --scenario soak` works on a recorded soak). Reported: loop jitter and
overruns, faults by code, how each injection was met, recoveries, and whether the log holds
every frame each sender counted sending.
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_py.mechanics.geometry import default_geometry
from hil.host import HostError
from hil.logdata import LogData, frames_by_sender, frames_counted_by_senders
from hil.logquery import LogView
from hil.metrics import after_machine_stall, fault_transitions, late_sensor_frames
from hil.scenario import Analysis, Check, Scenario
from hil.scenarios.common import THESIS_PLATFORM_LIMITS
from hil.scenarios.rt_loop import loop_timing
from physics.constants import MM
from protocol.enums import EmuCommand, EmuFault, Fault, State, WaypointFlag

DEFAULT_SEED = 20161
MOVE_S = 2.0                    # one move of the loop
MOVE_ACCEL_S = 0.3
INJECT_WINDOW_S = (0.2, 1.6)    # when, into a move, the fault goes in
ATTRIBUTE_S = 1.0               # a fault this soon after an injection is that injection's
PERSISTENT_EVERY = 8            # on average one injection in 8 is persistent
RECOVERY_TRIES = 3              # recoveries in a row that may fail before the soak gives up


@dataclass(frozen=True)
class SoakFault:
    what: str
    fault: str                       # EMU_CTRL fault name
    params: tuple[int, int]          # FAULT_PARAM drawn uniformly from [lo, hi]
    expect: tuple[str, ...] = ()     # () transient: no fault; else the acceptable codes
    max_cycles: int = 0              # persistent: FAULT within this many cycles of the last valid frame

    @property
    def transient(self) -> bool:
        return not self.expect


# the same bounds as the fault matrix's cases 4a, 4d, 4f, 4g, 4h (transient), 4b and 4e
TRANSIENT = (SoakFault("1 LEG_STATE dropped", "DROP", (1, 1)),
             SoakFault("1 LEG_STATE with a bad CRC", "CORRUPT", (1, 1)),
             SoakFault("LEG_STATE duplicated", "DUPLICATE", (1, 50)),
             SoakFault("one swapped pair of LEG_STATE", "REORDER", (2, 2)),
             SoakFault("1 stale LEG_STATE (repeated counter)", "REPEAT", (1, 1)))
PERSISTENT = (SoakFault("10 LEG_STATE dropped", "DROP", (10, 10), ("SENSOR_TIMEOUT",), 5),
              SoakFault("20 LEG_STATE with a bad CRC", "CORRUPT", (20, 20), ("E2E_ERROR",), 3))


def classify(fault_name: str, param: int) -> SoakFault | None:
    """The soak fault an EMU_CTRL injection was (None: not one of the soak's)."""
    for kind in TRANSIENT + PERSISTENT:
        if kind.fault == fault_name and kind.params[0] <= param <= kind.params[1]:
            return kind
    return None


class Soak(Scenario):
    name = "soak"
    title = "realtime hexapod trajectory loop with random frame faults"
    chapter = "reliability (docs/MEASUREMENTS.md)"
    rig = "hexapod"
    pacing = "realtime"
    pacings = ("realtime",)
    controllers = ("model-based",)
    controller_overrides = THESIS_PLATFORM_LIMITS      # its loop's reliability, not the thesis's tracking

    def __init__(self, seconds: float = 60.0, seed: int = DEFAULT_SEED):
        self.seconds, self.seed = seconds, seed
        self.notes: list[str] = []
        self.recoveries: list[bool] = []
        self._counted: dict | None = None      # what the senders counted (a run, not a bare log)
        self._run = None

    def poses(self) -> list[tuple[tuple, tuple]]:
        """Up, across, across with a tilt, home: translations and a roll within the workspace."""
        x, y, z = (float(v) for v in default_geometry().home_position_m)
        up = z + 40.0 * MM
        return [((x, y, up), (0.0, 0.0, 0.0)), ((x + 20.0 * MM, y, up), (0.0, 0.0, 0.0)),
                ((x, y + 20.0 * MM, up), (math.radians(1.5), 0.0, 0.0)), ((x, y, z), (0.0, 0.0, 0.0))]

    # -- host side -------------------------------------------------------------------------
    def script(self, run) -> None:
        self.notes.clear()
        self.recoveries.clear()
        self._run = run
        seconds = self.seconds = run.options.duration_s or self.seconds
        rng = np.random.default_rng(self.seed)
        host, poses = run.host, self.poses()
        deadline = time.monotonic() + seconds
        k = 0
        moving = (State.RUNNING, State.STOPPING)         # CTRL_STATUS lags a move's end by up to 16 cycles
        while time.monotonic() < deadline:
            host.wait_until(lambda: host.state not in moving, run.cycles(1.0), what=None)
            if host.state is not State.READY:
                self._recover(run, f"{host.state.name if host.state else None} before move {k}")
                continue
            position, rpy = poses[k % len(poses)]
            k += 1
            try:
                host.waypoint(position, rpy_rad=rpy, segment_time_s=MOVE_S, accel_time_s=MOVE_ACCEL_S,
                              flags=WaypointFlag.LAST | WaypointFlag.START)
            except HostError as error:          # a fault between the check and the waypoint
                self.notes.append(f"move {k}: {error}")
                continue
            into = float(rng.uniform(*INJECT_WINDOW_S))
            run.wait_s(into)
            kinds = PERSISTENT if rng.integers(PERSISTENT_EVERY) == 0 else TRANSIENT
            kind = kinds[int(rng.integers(len(kinds)))]
            param = int(rng.integers(kind.params[0], kind.params[1] + 1))
            target = int(rng.integers(1, 7))
            host.emulator(EmuCommand.INJECT_FAULT, target=target, fault=EmuFault[kind.fault], param=param)
            run.wait_s(MOVE_S - into + 0.1)
        host.wait_until(lambda: host.state not in moving, run.cycles(1.0), what=None)
        if host.state is not State.READY:
            self._recover(run, "at the end")
        # home: the last recovery's move, and a clean end; a machine stall may fault it as it
        # may fault any move: recovered and moved again, as RECOVERY_TRIES allows
        for _ in range(RECOVERY_TRIES):
            try:
                host.waypoint(poses[-1][0], segment_time_s=MOVE_S, accel_time_s=MOVE_ACCEL_S,
                              flags=WaypointFlag.LAST | WaypointFlag.START)
                run.wait_motion_done(MOVE_S + 2.0)
                return
            except HostError as error:
                self.notes.append(f"home move: {error}")
            self._recover(run, "after the home move")
        raise HostError(f"soak: the home move failed {RECOVERY_TRIES} times")

    def _recover(self, run, why: str) -> None:
        """RESET + ENABLE after a fault; RECOVERY_TRIES failures in a row end the soak."""
        run.host.emulator(EmuCommand.CLEAR_ALL)
        try:
            run.recover_from_fault()
            ok = run.host.state is State.READY
        except HostError as error:
            self.notes.append(f"recovery ({why}): {error}")
            ok = False
        self.recoveries.append(ok)
        if len(self.recoveries) >= RECOVERY_TRIES and not any(self.recoveries[-RECOVERY_TRIES:]):
            raise HostError(f"soak: {RECOVERY_TRIES} recoveries in a row failed")

    # -- analysis --------------------------------------------------------------------------
    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        view = LogView(log, period, 6)
        seconds = log.n_cycles * period
        injections = _injections(log)
        transitions = [(t, cycle, Fault(code).name, code == Fault.OVERRUN or after_machine_stall(log, cycle, period))
                       for t, cycle, code in fault_transitions(log)]
        status = log.get("CTRL_STATUS")
        attributed: set[int] = set()
        judged = []
        t_first = float(np.nanmin(log.sync_time_s)) if log.n_cycles else 0.0
        for t_inject, target, kind, param in injections:
            k0 = view.cycle_at(t_inject)
            before = np.flatnonzero(status.time_s <= t_inject)
            faulted_before = len(before) and status["STATE"][before[-1]] == State.FAULT
            hits = [i for i, (t, *_) in enumerate(transitions) if t_inject <= t <= t_inject + ATTRIBUTE_S]
            first = transitions[hits[0]][2] if hits else None
            cycles = None
            if faulted_before or (hits and transitions[hits[0]][3] and first not in kind.expect):
                # a machine stall faulted the controller first: nothing to judge (the stall is counted)
                verdict, code = "spoiled", first
            else:
                code = first
                attributed.update(hits[:1])
                if kind.transient:
                    verdict = "ok" if code is None else "failed"
                else:
                    reaction = view.reaction_cycle(k0, "CW_M")
                    last = view.last_valid_frame_cycle(target, reaction) if reaction is not None else None
                    cycles = None if reaction is None or last is None else reaction - last
                    ok = code in kind.expect and cycles is not None and cycles <= kind.max_cycles
                    verdict = "ok" if ok else "failed"
            judged.append({"t_s": round(t_inject - t_first, 3), "what": kind.what, "leg": target, "param": param,
                           "transient": kind.transient, "fault": code, "cycles": cycles, "verdict": verdict})
        unattributed = [(code, stall) for i, (_, _, code, stall) in enumerate(transitions) if i not in attributed]
        stalls = sum(1 for _, stall in unattributed if stall)
        unexpected = [code for code, stall in unattributed if not stall]
        transient = [j for j in judged if j["transient"] and j["verdict"] != "spoiled"]
        persistent = [j for j in judged if not j["transient"] and j["verdict"] != "spoiled"]
        spoiled = sum(1 for j in judged if j["verdict"] == "spoiled")
        by_code = dict(Counter(code for _, _, code, _ in transitions))
        recoveries = _recoveries(log, transitions)
        timing = loop_timing(log, period, out, "soak")
        checks = [
            Check("ran for the requested time", seconds >= 0.95 * self.seconds, f"{seconds:.1f} s of cycles",
                  f">= {self.seconds:g} s"),
            Check("faults injected", len(judged) >= seconds / (MOVE_S + 0.5) * 0.8,
                  f"{len(transient)} transient, {len(persistent)} persistent, {spoiled} spoiled by a machine stall",
                  f"one per move (>= {int(seconds / (MOVE_S + 0.5) * 0.8)})"),
            Check("transient faults: rejected, no fault", all(j["verdict"] == "ok" for j in transient),
                  f"{_count_ok(transient)} of {len(transient)}", "all"),
            Check("persistent faults: FAULT with their code within their count",
                  all(j["verdict"] == "ok" for j in persistent),
                  f"{_count_ok(persistent)} of {len(persistent)}; cycles "
                  f"{sorted({j['cycles'] for j in persistent if j['cycles'] is not None})}", "all"),
            Check("no fault without a cause (other than a machine stall)", not unexpected,
                  f"{unexpected or 'none'}", "none"),
            Check("every fault recovered (RESET + ENABLE -> READY, then a move)",
                  recoveries["recovered"] == recoveries["faults"],
                  f"{recoveries['recovered']} of {recoveries['faults']}", "all"),
            Check("faults after a machine stall, without an injection", stalls == 0, f"{stalls}", "0",
                  required=False),
        ]
        counted = self._sender_counts()
        in_log = None if counted is None else frames_by_sender(log.path)    # reads the whole log once
        if counted is not None:
            checks.append(Check("the log holds every frame each sender counted sending", in_log == counted,
                                f"log {in_log}", f"counted {counted}"))
        metrics = {"seconds": round(seconds, 2), "cycles": log.n_cycles, "seed": self.seed,
                   "injections": judged, "faults_by_code": by_code, "machine_stalls": stalls,
                   "unexpected_faults": unexpected, "recoveries": recoveries,
                   "late_sensor_frames": late_sensor_frames(log, 0, log.n_cycles, period),
                   "frames_rejected": log.e2e_errors, "host_notes": list(self.notes),
                   "log_vs_senders": None if counted is None else {"log": in_log, "counted": counted},
                   **timing.metrics}
        table = ["| injected | count | met as bound | faults |", "|---|---|---|---|"]
        for what in sorted({j["what"] for j in judged}):
            rows = [j for j in judged if j["what"] == what]
            faults = sorted({j["fault"] for j in rows if j["fault"]})
            table.append(f"| {what} | {len(rows)} | {_count_ok(rows)} | {faults or 'none'} |")
        summary = (f"faults by code {by_code or 'none'}; machine stalls {stalls}; recoveries "
                   f"{recoveries['recovered']}/{recoveries['faults']}; frames rejected {log.e2e_errors}")
        return Analysis(metrics, {}, checks + timing.checks, timing.figures,
                        ["\n".join(table) + "\n\n" + summary] + timing.tables)

    def _sender_counts(self) -> dict | None:
        """After a run: what each sender counted (children's summaries, the host's counter)."""
        run = self._run
        if run is None:
            return None
        children = {}
        for child in run.children:
            path = run.out / f"{child.name}.json"
            if not path.is_file():
                return None
            children[child.name] = json.loads(path.read_text())
        return frames_counted_by_senders(children, run.host.frames_sent)


def _count_ok(rows: list[dict]) -> int:
    return sum(1 for j in rows if j["verdict"] == "ok")


def _injections(log: LogData) -> list[tuple[float, int, SoakFault, int]]:
    """Every soak injection in the log: (time, target leg, kind, param)."""
    out = []
    for e in log.events_named("EMU_CTRL"):
        if int(e.values["COMMAND"]) != EmuCommand.INJECT_FAULT:
            continue
        kind = classify(_fault_name(int(e.values["FAULT"])), int(e.values["FAULT_PARAM"]))
        if kind is not None:
            out.append((e.time_s, int(e.values["TARGET"]), kind, int(e.values["FAULT_PARAM"])))
    return out


def _recoveries(log: LogData, transitions: list) -> dict:
    """A fault is recovered when, after it, the controller is READY again and then RUNNING."""
    s = log.get("CTRL_STATUS")
    recovered = 0
    for t, *_ in transitions:
        after = s["STATE"][s.time_s > t]
        ready = np.flatnonzero(after == State.READY)
        if len(ready) and np.any(after[ready[0]:] == State.RUNNING):
            recovered += 1
    return {"faults": len(transitions), "recovered": recovered}


def _fault_name(code: int) -> str:
    """EMU_CTRL.FAULT's name ("" for a code the DBC does not know)."""
    try:
        return EmuFault(code).name
    except ValueError:
        return ""
