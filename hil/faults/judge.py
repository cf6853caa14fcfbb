"""The fault matrix's judgement of each case from the recorded log: the reaction's reason and
delay, the hold after it, the excursion of the platform (EMU_TRUTH), and for transient
faults the distance from the no-fault probe. One judge per case kind (`JUDGES`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from firmware_py.config import load_config
from hil.faults.cases import (
    ENCODER_COUNT_M,
    HOLD_MOTION_MAX_M,
    HOLD_WITHIN_PERIODS,
    INJECT_AT_S,
    OBSERVE_S,
    PROBE_SEGMENT_S,
    REST_AFTER_S,
    REST_SPAN_S,
    REST_SWING_MAX_M,
    TRANSIENT_MAX_M,
    TRANSIENT_WINDOW_S,
    Case,
    CaseKind,
    Marks,
)
from hil.logquery import LogView
from plant_emulator.emulator import FAULT_ONSET_EVENT, SYNC_TIMEOUT_EVENT
from protocol.enums import AckKind, Command

# a controlled stop (firmware_py/supervision/stopping.py) keeps the healthy legs ACTIVE this long at most
CONTROLLED_STOP_S = load_config().supervisor.controlled_stop_s


def _mm(value) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{value * 1e3:.2f} mm"


def _cycles(view: LogView, cycles: int | None) -> str:
    """A detection delay in cycles and milliseconds."""
    return "n/a cycles" if cycles is None else f"{cycles} cycles ({cycles * view.period_s * 1e3:.0f} ms)"

def judge_baseline(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    faults = view.faults_between(mark.t_start, mark.t_end)
    ran = not math.isnan(mark.t_start) and "host_error" not in mark.extra
    measured = f"faults {faults or 'none'}" + ("" if ran else "; the probe did not run")
    legs = platform = None
    if baseline is not None and mark is not baseline:    # the same probe again: the comparison's floor
        legs, platform = deviation_from(view, mark, baseline)
        measured += (f"; legs {_mm(legs)}, platform {_mm(platform)} from the first no-fault run "
                     f"(from {INJECT_AT_S:g} s into the probe)")
    return ran and not faults, measured, {"faults": faults, "leg_deviation_m": legs,
                                          "platform_deviation_m": platform}

def judge_transient(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    """No fault and the legs within TRANSIENT_MAX_M of the no-fault run; or, where the case
    allows one (random frame loss: five lost in a row), only that fault."""
    faults = view.faults_between(mark.t_start, mark.t_end)
    legs, platform = deviation_from(view, mark, baseline)
    rejected = view.rejected_between(mark.case.target, mark.t_inject, mark.t_end)
    allowed = bool(faults) and set(faults) <= set(mark.case.expect)
    passed = allowed or (not faults and legs is not None and legs <= TRANSIENT_MAX_M + 1e-9)   # inclusive
    counts = (f"leg {mark.case.target}: {rejected['missing']} cycles without its frame, "
              f"{rejected['rejected']} frames rejected")
    measured = (f"no fault; legs {_mm(legs)} (platform {_mm(platform)}) from the no-fault run after the injection; "
                f"{counts}" if not faults else f"FAULT {faults}{' (allowed)' if allowed else ''}; {counts}")
    return passed, measured, {"faults": faults, "leg_deviation_m": legs, "platform_deviation_m": platform,
                              **rejected}

def judge_fault(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    """Persistent and plant faults: the reason, the cycles to the reaction, the excursion, and
    the platform at rest REST_AFTER_S after the reaction."""
    c = mark.case
    k0 = first_affected_cycle(view, mark, c, run_dir)
    reaction = view.reaction_cycle(k0, "CW_M")
    code = view.fault_code_after(k0)
    cycles = None if reaction is None or k0 is None else reaction - k0 + 1
    judged = cycles
    excursion = view.excursion(mark.t_inject, OBSERVE_S)
    all_held = view.all_held_cycle(reaction)     # a controlled stop's end, else the reaction
    held = (all_held is not None and (all_held - reaction) * view.period_s <= CONTROLLED_STOP_S + 2 * view.period_s
            and view.held_after(all_held))
    measured = f"{code} after {_cycles(view, cycles)}"
    if c.kind is CaseKind.PERSISTENT and reaction is not None:
        # the configured counts are of cycles in a row without a valid frame: a frame
        # accepted in between (a reordered pair's first) starts them again
        last = view.last_valid_frame_cycle(c.target, reaction)
        judged = reaction - last if last is not None and last >= (k0 or 0) else cycles
        measured += f" ({judged} since its last valid frame)"
    passed = (code in c.expect and judged is not None and judged <= c.max_cycles and held)
    path = into_probe_s = None
    if c.kind is CaseKind.PLANT:
        path = path_excursion(view, mark, baseline)
        passed = passed and (c.path_max_m == math.inf or (path is not None and path <= c.path_max_m))
        leg = view.controller_fault_leg(mark.t_inject, mark.t_inject + OBSERVE_S)
        measured += f" (leg {leg})" if leg else ""
        start = waypoint_ack_cycle(view, mark)
        into_probe_s = None if start is None or k0 is None else round((k0 - start) * view.period_s, 3)
        measured += f"; onset {into_probe_s} s into the probe" if into_probe_s is not None else ""
        measured += f"; off the no-fault path {_mm(path)}"
    swing = view.swing_after(reaction, REST_AFTER_S, REST_SPAN_S)
    at_rest = swing is not None and swing <= REST_SWING_MAX_M
    passed = passed and at_rest
    measured += (f"; excursion {_mm(excursion)}; VALVE_CMD every cycle after it with M = 0: {held}"
                 f"; {REST_AFTER_S:g} s after it swinging {_mm(swing)}")
    if c.kind is CaseKind.PERSISTENT:
        rejected = view.rejected_between(c.target, mark.t_inject, mark.t_end)
        measured += f"; {rejected['rejected']} frames rejected"
    return passed, measured, {"code": code, "cycles": cycles, "detection_ms": None if cycles is None else
                              round(cycles * view.period_s * 1e3, 1), "excursion_m": excursion,
                              "path_excursion_m": path, "held": held, "swing_after_m": swing,
                              "onset_into_probe_s": into_probe_s,
                              "at_rest": at_rest}


def judge_estop(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    ack_cycle = view.ack_cycle(Command.ESTOP, mark.t_inject)
    disabled = view.reaction_cycle(ack_cycle, "CW_D")
    same = ack_cycle is not None and disabled == ack_cycle
    valve_off = view.valve_state_from(disabled, 1)
    excursion = view.excursion(mark.t_inject, OBSERVE_S)
    measured = (f"D = 0 in the ESTOP's cycle: {same} (ack cycle {ack_cycle}, D = 0 cycle {disabled}); "
                f"valves DISABLED {valve_off} cycles later; excursion {_mm(excursion)}")
    return same and valve_off is not None and valve_off <= 1, measured, {
        "ack_cycle": ack_cycle, "disabled_cycle": disabled, "excursion_m": excursion}

def judge_waypoints(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    acks = mark.extra.get("acks", {})
    expected = {"outside the workspace": ("OUTSIDE_WORKSPACE",),
                "through a singularity (yaw 90 deg)": ("SINGULAR", "OUTSIDE_WORKSPACE"),
                "too fast (30 mm in 0.1 s)": ("TOO_FAST",), "sequence gap (+5)": ("SEQUENCE_GAP",)}
    ok = all(acks.get(k) in allowed for k, allowed in expected.items()
             if k in acks or not k.startswith("through"))          # no singularity on the bench
    ok = ok and acks.get("NaN field", "").startswith("REFUSED")
    # zero motion: never RUNNING, and no leg's encoder moves by more than its hold hunts over:
    # one count (a position loop cannot see less), or what the legs spanned holding at rest in
    # as long a window just before (a payload's hold hunts over two). The platform's own range
    # (truth) is reported beside its range holding at rest then: both hunt (0.1-0.3 mm on the
    # hexapod, one count of a slender leg amplified)
    span = mark.t_end - mark.t_inject
    k0, k1 = view.cycle_at(mark.t_inject), view.cycle_at(mark.t_end)
    legs = view.leg_range(k0, k1)
    hold = view.leg_range(view.cycle_at(mark.t_inject - span), k0)
    bound = max(ENCODER_COUNT_M, hold or 0.0) * 1.001
    motion = view.truth_range(mark.t_inject, mark.t_end)
    floor = view.truth_range(mark.t_inject - span, mark.t_inject)
    states = view.states_between(mark.t_inject, mark.t_end)
    still = "RUNNING" not in states and legs is not None and legs <= bound
    measured = "; ".join(f"{k}: {v}" for k, v in acks.items()) + \
        (f"; states {states}; legs moved "
         f"{'n/a' if legs is None else f'{legs / ENCODER_COUNT_M:.0f}'} encoder count(s) at most (bound "
         f"{bound / ENCODER_COUNT_M:.0f}: the hold's before); "
         f"platform range {_mm(motion)} (holding at rest before: {_mm(floor)})")
    return ok and still, measured, {"acks": acks, "leg_range_m": legs, "hold_leg_range_m": hold,
                                    "platform_range_m": motion, "hold_platform_range_m": floor, "states": states}

def judge_babble(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
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

def judge_stall(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
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

def judge_kill(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
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
    late_ms = emulator_trip_late_ms(run_dir, mark.t_inject - 0.01, mark.t_inject + 1.0)
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

def emulator_events(run_dir: Path | None, event: str, t0: float, t1: float) -> list[dict]:
    """The emulators' own event lines of one kind (JSON after `event`) stamped in [t0, t1]:
    from stderr, which a killed emulator has written too (it leaves no summary)."""
    found = []
    for path in sorted(run_dir.glob("emulator*.stderr.log")) if run_dir is not None else ():
        for line in path.read_text(errors="replace").splitlines():
            if line.startswith(event):
                try:
                    record = json.loads(line[len(event):])
                except ValueError:
                    continue
                if t0 <= record["t_epoch_s"] <= t1:
                    found.append(record)
    return found


def emulator_trip_late_ms(run_dir: Path | None, t0: float, t1: float) -> float | None:
    """The emulator's own record of its SYNC-watchdog trips in [t0, t1] (None: none)."""
    late = [trip["late_ms"] for trip in emulator_events(run_dir, SYNC_TIMEOUT_EVENT, t0, t1)]
    return max(late) if late else None


def onset_cycle(view: LogView, mark: Marks, run_dir: Path | None) -> int | None:
    """The first cycle that sees an injected fault: the SYNC the emulator handled first after
    the EMU_CTRL (its onset event), found in the log by its counter and time."""
    c = mark.case
    for onset in emulator_events(run_dir, FAULT_ONSET_EVENT, mark.t_inject, mark.t_inject + OBSERVE_S):
        if onset["fault"] == c.fault and onset["target"] == c.target:
            return view.cycle_of_sync(onset["sync_counter"], onset["t_epoch_s"])
    return None


def judge_kill_emulator(view: LogView, mark: Marks, baseline: Marks | None, run_dir: Path | None):
    k0 = view.cycle_at(mark.t_inject)
    last_frame = view.last_leg_state_cycle_before(mark.t_inject + 0.5)
    reaction = view.reaction_cycle(k0, "CW_M")
    code = view.fault_code_after(k0)
    cycles = None if reaction is None or last_frame is None else reaction - last_frame
    held = view.held_after(reaction, until=mark.t_inject + OBSERVE_S)
    passed = code in mark.case.expect and cycles is not None and cycles <= mark.case.max_cycles and held
    measured = (f"{code} {_cycles(view, cycles)} after the last LEG_STATE; VALVE_CMD (finite, M = 0) every cycle "
                f"after: {held}")
    return passed, measured, {"code": code, "cycles": cycles, "held": held}


def first_affected_cycle(view: LogView, mark: Marks, case: Case, run_dir: Path | None) -> int | None:
    """Frame faults: the first cycle from the injection without an OK LEG_STATE of the
    target; a reboot: its boot-up's; plant faults: the fault's onset cycle (None: the
    emulator never applied it)."""
    if case.kind is CaseKind.PLANT:
        return onset_cycle(view, mark, run_dir)
    k0 = view.cycle_at(mark.t_inject)
    if k0 is None:
        return k0
    if case.kind is CaseKind.REBOOT:          # the log's LEG_STATE carries a silent encoder's last position
        return k0
    s = view.log.get(f"LEG_STATE_{case.target}")
    present = set(s.cycle[s.cycle >= k0].tolist())
    for k in range(k0, min(k0 + 50, view.log.n_cycles)):
        if k not in present:
            return k
    return None

def deviation_from(view: LogView, mark: Marks, baseline: Marks | None) -> tuple[float | None, float | None]:
    """What the fault changed: the largest change, over TRANSIENT_WINDOW_S from the injection,
    of this probe's difference from the baseline's (the probes aligned at the commit of their
    first waypoint): (leg strokes, platform distance). The difference one cycle before the
    injection is subtracted: it cannot be the fault's (two no-fault probes start from rest
    0.25-0.6 mm apart on the hexapod, where each leg's stiction left it). The window ends
    before the probe decelerates, where two no-fault probes part again by their stops."""
    if baseline is None:
        return None, None
    ka, kb = waypoint_ack_cycle(view, mark), waypoint_ack_cycle(view, baseline)
    if ka is None or kb is None:
        return None, None
    k_inject = view.cycle_at(mark.t_inject) if not math.isnan(mark.t_inject) else None
    skip = k_inject - ka if k_inject is not None else int(round(INJECT_AT_S / view.period_s))
    span = TRANSIENT_WINDOW_S + view.period_s                    # from the cycle before the injection
    a, b = view.truth_window(ka + skip - 1, span), view.truth_window(kb + skip - 1, span)
    platform = None if a is None or b is None else _largest_change(a - b, lambda d: np.linalg.norm(d, axis=1))
    la, lb = _legs_window(view, ka + skip - 1, span), _legs_window(view, kb + skip - 1, span)
    legs = None if la is None or lb is None else _largest_change(la - lb, np.abs)
    return legs, platform


def path_excursion(view: LogView, mark: Marks, baseline: Marks | None) -> float | None:
    """How far the platform strayed from the no-fault probe's path over OBSERVE_S from the
    injection: each position's distance to the nearest of the baseline's, less that distance
    the cycle before the injection. A stop along the path is no excursion; the swing a locked
    leg's error causes is."""
    if baseline is None or math.isnan(mark.t_inject):
        return None
    ka, kb, k_inject = waypoint_ack_cycle(view, mark), waypoint_ack_cycle(view, baseline), view.cycle_at(mark.t_inject)
    if ka is None or kb is None or k_inject is None:
        return None
    span = 2 * PROBE_SEGMENT_S
    path = view.truth_window(kb, span)
    after = view.truth_window(k_inject - 1, OBSERVE_S + view.period_s)
    if path is None or after is None:
        return None
    path = path[np.all(np.isfinite(path), axis=1)]
    after = after[np.all(np.isfinite(after), axis=1)]
    distance = np.linalg.norm(after[:, None, :] - path[None, :, :], axis=2).min(axis=1)
    return float(np.max(distance - distance[0]))


def _largest_change(difference: np.ndarray, size) -> float | None:
    """The largest size(row - first row); None when the first row (the reference) is incomplete."""
    if not np.all(np.isfinite(difference[0])):
        return None
    return float(np.nanmax(size(difference - difference[0])))

def _legs_window(view: LogView, k0: int | None, span: float):
    n = int(round(span / view.period_s))
    if k0 is None or k0 + n > len(view.legs):
        return None
    return view.legs[k0:k0 + n]

def waypoint_ack_cycle(view: LogView, mark: Marks) -> int | None:
    """The cycle the probe's first waypoint was committed (its CTRL_ACK)."""
    seq = mark.extra.get("probe_seq")
    for e in view.log.events_named("CTRL_ACK"):
        if (e.time_s >= mark.t_start and int(e.values["KIND"]) == AckKind.WAYPOINT
                and int(e.values["SEQ"]) == seq):
            return e.cycle
    return None

JUDGES = {
    CaseKind.BASELINE: judge_baseline,
    CaseKind.TRANSIENT: judge_transient,
    CaseKind.PERSISTENT: judge_fault,
    CaseKind.REBOOT: judge_fault,
    CaseKind.PLANT: judge_fault,
    CaseKind.ESTOP: judge_estop,
    CaseKind.WAYPOINTS: judge_waypoints,
    CaseKind.BABBLE: judge_babble,
    CaseKind.STALL: judge_stall,
    CaseKind.KILL: judge_kill,
    CaseKind.KILL_EMULATOR: judge_kill_emulator,
}
