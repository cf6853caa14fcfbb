"""Run a campaign on Dask: a `LocalCluster` on this machine, or a running scheduler's address.
Each run is a task (`execute.run_one`); the rows are written as they come (Parquet and CSV,
rewritten whole after each run, so an interrupted campaign keeps what finished). A task whose
worker died is re-queued by the scheduler; one that keeps killing workers is recorded failed.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from hil.campaign.execute import base_row, run_one
from hil.campaign.spec import Campaign
from program.errors import UserInputError

RESULTS = "results"                    # results.parquet, results.csv
STATUSES = ("ok", "failed", "hung", "error", "spoiled")
ROOT = Path(__file__).resolve().parents[2]


class CampaignError(UserInputError):
    pass


def read_results(out: Path) -> list[dict]:
    """The rows a previous campaign wrote to `out` ([] when none)."""
    import pyarrow.parquet as pq
    path = out / f"{RESULTS}.parquet"
    if not path.exists():
        return []
    try:
        return pq.read_table(path).to_pylist()
    except Exception as error:              # a damaged file: say which, do not overwrite it
        raise CampaignError(f"--resume: {path} cannot be read ({error})") from None


def write_results(out: Path, rows: list[dict]) -> None:
    """Both files, replaced atomically (a reader never sees half a table)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq
    columns = sorted({k for row in rows for k in row}, key=_column_order)
    table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in rows])
    for suffix, write in (("parquet", pq.write_table), ("csv", pcsv.write_csv)):
        tmp = out / f".{RESULTS}.{suffix}.tmp"
        write(table, tmp)
        tmp.replace(out / f"{RESULTS}.{suffix}")


def _column_order(name: str) -> tuple:
    head = ("run_id", "status", "passed", "reason", "wall_s", "out_dir")
    if name in head:
        return (0, head.index(name), name)
    return (1 if name.startswith("param.") else 2 if name.startswith("metric.") else 3, 0, name)


def tasks(campaign: Campaign, out: Path) -> list[dict]:
    from plant_emulator.params import load_raw
    nominal = load_raw(None, None)
    return [{"run_id": run.run_id, "params": run.params, "scenario": campaign.scenario, "short": campaign.short,
             "timeout_s": campaign.timeout_s, "out_dir": str((out / "runs" / run.run_id).resolve()),
             "controller_config": campaign.controller_sections(run.params),
             "emulator_config": campaign.emulator_sections(run.params, nominal), "cwd": str(ROOT)}
            for run in campaign.runs()]


def _client(scheduler: str | None, workers: int):
    """A client of the scheduler at `scheduler`, or of a new LocalCluster of `workers`
    single-threaded worker processes (a HIL run is three processes already)."""
    from dask.distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError, ValueError) as error:
            raise CampaignError(f"--scheduler {scheduler}: cannot connect ({error})") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster


def _failed_row(task: dict, reason: str) -> dict:
    return {**base_row(task, task["out_dir"]), "status": "error", "passed": False, "reason": reason,
            "wall_s": math.nan}


def run_campaign(campaign: Campaign, out: Path, scheduler: str | None = None, workers: int = 2,
                 resume: bool = False, progress=None) -> dict:
    """Run every task not already in `out`'s table (`resume`); returns the summary."""
    from dask.distributed import as_completed
    out.mkdir(parents=True, exist_ok=True)
    previous = read_results(out) if resume else []
    if not resume and (out / f"{RESULTS}.parquet").exists():
        raise CampaignError(f"--out {out}: holds a campaign's results already (--resume to continue it)")
    done_ids = {row["run_id"] for row in previous}
    todo = [t for t in tasks(campaign, out) if t["run_id"] not in done_ids]
    rows = list(previous)
    progress = progress or _Progress(len(todo), len(previous))
    started = time.monotonic()
    client, cluster = _client(scheduler, workers)
    try:
        # pure=False: a re-run is a new experiment; the scheduler re-queues a dead worker's task
        futures = {client.submit(run_one, task, pure=False, key=f"run-{task['run_id']}"): task
                   for task in todo}
        for future in as_completed(futures):
            task = futures[future]
            try:
                row = future.result()
            except Exception as error:                   # KilledWorker, or a bug in the worker's code
                row = _failed_row(task, f"{type(error).__name__}: {error}"[:300])
            rows.append(row)
            write_results(out, rows)
            progress.update(row)
        n_workers = len(client.scheduler_info().get("workers", {}))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    if not rows:
        write_results(out, rows)
    wall = time.monotonic() - started
    counts = {s: sum(1 for r in rows if r.get("status") == s) for s in STATUSES}
    return {"campaign": campaign.name, "scenario": campaign.scenario, "runs": len(rows), "ran": len(todo),
            "skipped": len(previous), **counts, "workers": n_workers, "wall_s": round(wall, 1),
            "runs_per_minute": round(len(todo) / wall * 60.0, 2) if todo and wall > 0 else None,
            "results": str(out / f"{RESULTS}.parquet")}


class _Progress:
    """One line per finished run on stderr: done/total, failed, ETA."""

    def __init__(self, total: int, skipped: int):
        self.total, self.done, self.failed, self.started = total, 0, 0, time.monotonic()
        if skipped:
            print(f"campaign: {skipped} runs already in the table, skipped", file=sys.stderr, flush=True)

    def update(self, row: dict) -> None:
        self.done += 1
        self.failed += row.get("status") != "ok"
        elapsed = time.monotonic() - self.started
        eta = elapsed / self.done * (self.total - self.done)
        reason = f": {row['reason']}" if row.get("reason") else ""
        print(f"campaign: {self.done}/{self.total} done, {self.failed} not ok, ETA {eta / 60.0:.1f} min "
              f"({row['run_id']} {row.get('status')}{reason})", file=sys.stderr, flush=True)
