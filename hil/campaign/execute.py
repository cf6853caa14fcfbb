"""One campaign run on a worker: `hydrapod hil run` as a process of its own (which starts the
emulator and the controller on a fresh on-host multicast group and port, hop limit 0), its
configs written beside its output. A run that fails or hangs comes back as a row with its
reason and its logs on disk; nothing here raises for a failed run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from firmware_py.supervision.diagnostics import PEAK_KEYS
from hil.experiments import PLANNED_TIME_SCALES
from hil.runner import toml_sections

METRICS_PREFIX = "metric."
CONTROLLER_SUMMARY_KEYS = ("faults", *PEAK_KEYS, "missing_frames")
SPOILED_RETRIES = 2                # a lockstep run whose frames missed the window runs again


def command(task: dict, out: Path) -> list[str]:
    """The `hydrapod hil run` command line of a task."""
    params = task["params"]
    argv = [sys.executable, "-m", "hil.cli", "hil", "run", task["scenario"], "--pacing", "lockstep",
            "--out", str(out / "run"), "--json", "--no-plots"]
    if task["short"]:
        argv.append("--short")
    if "controller" in params:
        argv += ["--controllers", params["controller"]]
    if "load_kg" in params:
        argv += ["--loads", repr(float(params["load_kg"]))]
    if params.get("fault"):
        argv += ["--inject", params["fault"]]
    if "position_mm" in params:
        argv += ["--positions", repr(float(params["position_mm"]))]
    if "time_scale" in params:
        scale = params["time_scale"]
        argv += ["--time-scale", scale if scale in PLANNED_TIME_SCALES else repr(float(scale))]
    if task["controller_config"]:
        argv += ["--controller-config", str(out / "controller-overrides.toml")]
    if task["emulator_config"]:
        argv += ["--emulator-config", str(out / "emulator-overrides.toml")]
    return argv


def flatten_metrics(doc: dict, controller: str | None) -> dict:
    """Every number the run reports, as `metric.<path>` columns. A level named after the run's
    controller is dropped, so runs of different controllers share their columns."""
    row: dict = {}

    def walk(prefix: str, value) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                if str(key).startswith("_"):
                    continue
                walk(prefix if key == controller else f"{prefix}.{key}" if prefix else str(key), item)
        elif isinstance(value, bool):
            row[METRICS_PREFIX + prefix] = bool(value)
        elif isinstance(value, (int, float)):
            row[METRICS_PREFIX + prefix] = float(value)

    walk("", doc.get("metrics", {}).get("summary", doc.get("metrics", {})))
    for check in doc.get("checks", []):
        row[f"check.{check['name']}"] = bool(check["passed"])
    # the controllers' own summaries: faults latched and the monitors' largest ratio before
    # the first (the false-alarm margin's inverse), the worst over the run's controllers
    summaries = [child.get("summary", {}) for name, child in doc.get("children", {}).items()
                 if name.startswith("controller")]
    for key in CONTROLLER_SUMMARY_KEYS:
        values = [float(s[key]) for s in summaries if isinstance(s.get(key), (int, float))]
        if values:
            row[f"{METRICS_PREFIX}controller.{key}"] = max(values)
    return row


def base_row(task: dict, out_dir: Path | str) -> dict:
    """A run's row before its outcome: its hash, parameters and output directory."""
    return {"run_id": task["run_id"], **{f"param.{k}": v for k, v in task["params"].items()},
            "out_dir": str(out_dir)}


def _attempt_dir(run_dir: Path) -> Path:
    """A directory of its own for this attempt: a run re-queued after its worker died gets a
    new one, while the first attempt's orphaned process may still be writing the old."""
    run_dir.mkdir(parents=True, exist_ok=True)
    for attempt in range(1000):
        try:
            (run_dir / f"attempt-{attempt}").mkdir()
            return run_dir / f"attempt-{attempt}"
        except FileExistsError:
            continue
    raise RuntimeError(f"{run_dir}: 1000 attempts")


def run_one(task: dict) -> dict:
    """Run one task; its row: parameters, status (ok, failed, hung, error, spoiled), reason,
    wall time, output directory, and the run's metrics. A lockstep run in which sensor frames
    missed the controller's window was not in lockstep (the machine was too loaded to answer
    within `lockstep_timeout_ms`): its faults are not the plant's. It runs again, at most
    SPOILED_RETRIES times; still spoiled, it is recorded as such."""
    spoiled = 0
    while True:
        row = _run_attempt(task)
        missing = row.get(f"{METRICS_PREFIX}controller.missing_frames", 0.0)
        if row["status"] in ("hung", "error") or not missing:
            break
        spoiled += 1
        if spoiled > SPOILED_RETRIES:
            row = {**row, "status": "spoiled", "passed": False,
                   "reason": f"lockstep frames missed their window in {spoiled} attempts ({missing:g} in the last): "
                             f"the machine was too loaded, use fewer --workers"}
            break
    return {**row, "spoiled_attempts": spoiled}


def _run_attempt(task: dict) -> dict:
    out = _attempt_dir(Path(task["out_dir"]))
    (out / "task.json").write_text(json.dumps(task, indent=1, default=float))
    if task["controller_config"]:
        (out / "controller-overrides.toml").write_text(toml_sections(task["controller_config"]))
    if task["emulator_config"]:
        (out / "emulator-overrides.toml").write_text(toml_sections(task["emulator_config"]))
    row = {**base_row(task, out), "attempt": int(out.name.split("-")[1]), "worker_pid": os.getpid()}
    started = time.monotonic()
    proc = subprocess.Popen(command(task, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, cwd=task.get("cwd"))
    try:
        stdout, stderr = proc.communicate(timeout=task["timeout_s"])
        hung = False
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)              # the run and the daemons it started
        stdout, stderr = proc.communicate()
        hung = True
    row["wall_s"] = round(time.monotonic() - started, 3)
    (out / "run.stdout.log").write_text(stdout)
    (out / "run.stderr.log").write_text(stderr)
    tail = (stderr.strip().splitlines() or [""])[-1][:300]
    if hung:
        return {**row, "status": "hung", "passed": False, "reason": f"still running after {task['timeout_s']:g} s"}
    try:
        doc = json.loads(stdout)
    except json.JSONDecodeError:
        return {**row, "status": "error", "passed": False,
                "reason": f"exit {proc.returncode}, no metrics: {tail or 'no output'}"}
    row.update(flatten_metrics(doc, task["params"].get("controller")))
    failed = [c["name"] for c in doc.get("checks", []) if c.get("required") and not c.get("passed")]
    passed = bool(doc.get("passed"))
    reason = doc.get("failure") or ("; ".join(failed) if failed else "")
    return {**row, "status": "ok" if passed else "failed", "passed": passed, "reason": reason}
