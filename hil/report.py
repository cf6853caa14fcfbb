"""metrics.json and report.md of a run (or of an analysed log)."""

from __future__ import annotations

import json
from pathlib import Path

from hil.logdata import LogData
from hil.metrics import ctrl_status_timing
from hil.scenario import Scenario


def write_outputs(scenario: Scenario, log: LogData, out: Path, extra: dict, rate_hz: float = 500.0,
                  plots: bool = True) -> dict:
    analysis = scenario.analyze(log, out if plots else None, rate_hz)
    timing = ctrl_status_timing(log)
    failure = extra.get("failure")
    doc = {
        "scenario": scenario.name,
        "passed": bool(all(c.passed for c in analysis.checks if c.required) and analysis.checks and not failure),
        # the same without the speed goals: what the test suite asserts (`Check.benchmark`)
        "behaviour_passed": bool(all(c.passed for c in analysis.checks if c.required and not c.benchmark)
                                 and analysis.checks and not failure),
        "metrics": analysis.metrics,
        "thesis": analysis.thesis,
        "checks": [c.as_dict() for c in analysis.checks],
        "e2e_errors": log.e2e_errors,
        "overruns": timing["overruns"],
        "log": {"path": log.path, "frames": log.frames, "cycles": log.n_cycles, "lost_frames": log.lost_frames,
                "lost_by_message": log.lost, "unknown_frames": log.unknown_frames, "rx_status": log.rx_counts},
        "ctrl_status_timing": timing,
        "figures": [f.file for f in analysis.figures],
        "rate_hz": rate_hz,
        **extra,
    }
    (out / "metrics.json").write_text(json.dumps(doc, indent=1, default=_plain))
    (out / "report.md").write_text(format_report(scenario, doc, analysis))
    return doc


def _plain(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)


def format_checks(doc: dict) -> str:
    rows = ["| check | expected | measured | pass |", "|---|---|---|---|"]
    rows += [f"| {c['name']} | {c['expected']} | {c['measured']} | "
             f"{_verdict(c)}"
             f"{' (benchmark)' if c.get('benchmark') else ''} |"
             for c in doc["checks"]]
    return "\n".join(rows)


def _verdict(check: dict) -> str:
    if check["required"]:
        return "yes" if check["passed"] else "**no**"
    return "matches" if check["passed"] else "deviates (reported)"


def format_report(scenario: Scenario, doc: dict, analysis) -> str:
    lines = [f"# {scenario.name}: {scenario.title}", "",
             f"Thesis: {scenario.chapter}. Rig: {scenario.rig}. Result: **{'PASSED' if doc['passed'] else 'FAILED'}**.",
             ""]
    if doc.get("failure"):
        lines += ["## Run failure", "", "```", doc["failure"], "```", ""]
    lines += ["## Checks (thesis beside measured)", "", format_checks(doc), ""]
    for table in analysis.tables:
        lines += [table, ""]
    for figure in analysis.figures:
        lines += [f"### {figure.caption}", "", f"Beside: {figure.thesis}", "",
                  f"![{figure.caption}]({figure.file})", ""]
    t = doc["ctrl_status_timing"]
    lines += ["## Bus and timing (from the log)", "",
              f"- frames {doc['log']['frames']}, cycles {doc['log']['cycles']}, E2E errors {doc['e2e_errors']}, "
              f"frames missing from counter sequences {doc['log']['lost_frames']}",
              f"- overruns (CTRL_STATUS) {doc['overruns']}; controller period error per 16-cycle window "
              f"{t.get('period_error_us')}; compute time {t.get('compute_time_us')}"]
    if realtime_line(doc):
        lines.append(f"- {realtime_line(doc)}")
    if doc.get("failure") is None and "children" in doc:
        for name, child in doc["children"].items():
            lines.append(f"- {name}: exit {child['exit_status']}: `{child['summary_line']}`")
    budget = format_budget(doc)
    if budget:
        lines += ["", budget]
    return "\n".join(lines) + "\n"


def format_budget(doc: dict) -> str:
    """Where each process's cycle goes: the controller's phases per cycle and the emulator's per
    SYNC (p50 / p99 / max in us, each process's own clock), from their exit summaries."""
    rows = []
    for name, child in doc.get("children", {}).items():
        summary = child.get("summary") or {}
        phases = summary.get("timing", {}).get("phases_us") or summary.get("phases_us") or {}
        rows += [f"| {name} | {phase} | {p['p50']:g} | {p['p99']:g} | {p['max']:g} |" for phase, p in phases.items()]
    if not rows:
        return ""
    period_us = 1e6 / doc.get("rate_hz", 500.0)
    return "\n".join([f"## Cycle budget (period {period_us:g} us)", "",
                      "| process | phase | p50 us | p99 us | max us |", "|---|---|---|---|---|", *rows])


def format_terminal(doc: dict) -> str:
    lines = [f"{doc['scenario']}: {'PASSED' if doc['passed'] else 'FAILED'}"]
    for c in doc["checks"]:
        mark = ("ok" if c["passed"] else "FAIL") if c["required"] else ("ok" if c["passed"] else "deviates")
        kind = " (benchmark)" if c.get("benchmark") else ""
        lines.append(f"  [{mark}] {c['name']}{kind}: {c['measured']} (expected {c['expected']})")
    lines.append(f"  e2e_errors={doc['e2e_errors']} overruns={doc['overruns']} frames={doc['log']['frames']} "
                 f"lost={doc['log']['lost_frames']}")
    realtime = realtime_line(doc)
    if realtime:
        lines.append("  " + realtime)
    if doc.get("failure"):
        lines.append("  run failure: " + doc["failure"].replace("\n", "\n    "))
    return "\n".join(lines)


def realtime_line(doc: dict) -> str:
    """A realtime run's timing in one line: clean (no overrun, no emulator stall) or not, with
    the period error and compute time (CTRL_STATUS windows) and the emulator's stalls."""
    if doc.get("pacing") != "realtime":
        return ""
    t = doc.get("ctrl_status_timing", {})
    period, compute = t.get("period_error_us") or {}, t.get("compute_time_us") or {}
    emulator = ((doc.get("children") or {}).get("emulator") or {}).get("summary") or {}
    stalls, stall_max = emulator.get("host_stalls"), emulator.get("host_stall_max_ms")
    clean = doc.get("overruns") == 0 and stalls == 0
    return (f"realtime: {'clean' if clean else 'NOT clean'}: overruns {doc.get('overruns')}, period error p99 "
            f"{period.get('p99')} us (max {period.get('max')}), compute p99 {compute.get('p99')} us "
            f"(max {compute.get('max')}), emulator stalls {stalls} (max {stall_max} ms)")
