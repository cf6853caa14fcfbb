"""The fault matrix as a whole: its sessions, their run, the table (faults.md, faults.json)."""

from __future__ import annotations

import json
from pathlib import Path

from firmware_py.supervision.diagnostics import PEAK_KEYS
from hil.faults.cases import LOCKSTEP_CASES, VALVE_WATCHDOG_PERIODS, realtime_cases
from hil.faults.session import Session
from hil.runner import RunOptions, run_scenario

PACINGS = ("lockstep", "realtime")


def sessions(short: bool, pacings: tuple[str, ...] = PACINGS, devices: str = "hydrapod") -> list[Session]:
    """Full: every case on both rigs, the plant cases in both pacings. Short (make test): the
    hexapod, the plant cases in lockstep only. Stock CANopen devices: the cases an E2E check
    judges are not run (their frames carry none), and a stock node's reboot is run there alone."""
    cases = {"lockstep": LOCKSTEP_CASES, "realtime": realtime_cases(short)}
    if devices == "canopen":
        cases = {pacing: [c for c in listed if not c.e2e] for pacing, listed in cases.items()}
    else:
        cases = {pacing: [c for c in listed if not c.canopen_only] for pacing, listed in cases.items()}
    rigs = ("hexapod",) if short else ("hexapod", "testbench")
    return [Session(rig, pacing, cases[pacing]) for rig in rigs for pacing in PACINGS if pacing in pacings]


def run_matrix(out: Path, short: bool, bus: str | None = None, start_timeout_s: float = 90.0,
               pacings: tuple[str, ...] = PACINGS, payload_kg: float = 0.0, devices: str = "hydrapod") -> dict:
    """Every session's cases on `devices`; `payload_kg` on the hexapod's platform, declared to
    its controller."""
    results, runs = [], []
    for session in sessions(short, pacings, devices):
        payload = {"hexapod": {"payload_kg": payload_kg}} if payload_kg and session.rig == "hexapod" else {}
        options = RunOptions(out_dir=out / session.name, bus=bus, short=short, start_timeout_s=start_timeout_s,
                             valve_watchdog_periods=VALVE_WATCHDOG_PERIODS if session.pacing == "realtime" else None,
                             controller_config=payload, emulator_config=payload, devices=devices)
        doc = run_scenario(session, options)
        runs.append({"session": session.name, "passed": doc["passed"], "failure": doc.get("failure"),
                     "e2e_errors": doc["e2e_errors"], "wall_time_s": doc.get("wall_time_s"),
                     **{key: controllers_peak(doc, key) for key in PEAK_KEYS}})
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


def controllers_peak(doc: dict, key: str) -> float | None:
    """The controllers' largest `key` (`residual_peak`: residual / threshold before their first
    fault, the false-alarm margin's inverse; `supply_peak`, `spool_peak`, `attitude_peak`,
    `pressure_peak` the same for the supply samples, the spools, the IMU and the chambers),
    from their summaries; None when none reported it."""
    peaks = [child.get("summary", {}).get(key) for name, child in doc.get("children", {}).items()
             if name.startswith("controller")]
    peaks = [p for p in peaks if p is not None]
    return max(peaks) if peaks else None


def format_matrix(doc: dict) -> str:
    lines = ["# Fault-injection matrix", "", f"Result: **{'PASSED' if doc['passed'] else 'FAILED'}**", "",
             "| case | rig | fault | bound | measured | recovered (9) | pass |", "|---|---|---|---|---|---|---|"]
    for r in doc["cases"]:
        lines.append(f"| {r['key']} | {r['rig']} | {r['what']} | {r['bound']} | {r['measured']} | "
                     f"{r['recovered']} | {'yes' if r['passed'] else '**no**'} |")
    noted = [r for r in doc["cases"] if r["detail"].get("notes")]
    if noted:     # spoiled attempts and repeated recoveries (machine stalls), in the open
        lines += ["", "Notes:"] + [f"- {r['key']} ({r['rig']}): " + " | ".join(r["detail"]["notes"]) for r in noted]
    lines += ["", "| session | passed | wall s | E2E errors | residual / threshold before the first fault "
                  "| supply, the same | spool, the same | attitude, the same | chamber pressures, the same | failure |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for s in doc["sessions"]:
        peaks = " | ".join(str(s.get(key)) for key in PEAK_KEYS)
        lines.append(f"| {s['session']} | {s['passed']} | {s['wall_time_s']} | {s['e2e_errors']} | {peaks} | "
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
