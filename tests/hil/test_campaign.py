"""Issue 24: HIL campaigns on Dask. The spec is checked whole before anything runs; the smoke
campaign runs on a LocalCluster of 2 workers and on a real `dask scheduler` with two `dask
worker` processes, one of them killed mid-run (its run re-queued and completed); the table
is complete and `--resume` skips what it holds."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from hil.campaign.execute import flatten_metrics
from hil.campaign.spec import SCALES, SpecError, load_campaign
from hil.cli import main
from tests.support.cli import hydrapod

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "hil" / "campaigns" / "smoke.toml"
ROBUSTNESS = ROOT / "hil" / "campaigns" / "robustness-sha-step.toml"
BIN = Path(sys.executable).parent


def _spec(tmp_path, text: str) -> Path:
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return path


GOOD = '[campaign]\nscenario = "sha-step"\n[grid]\ncontroller = ["pi"]\n'


@pytest.mark.parametrize("text, culprit", [
    ('[campaign]\nscenario = "sha-stp"\n', "sha-stp"),
    ('[campaign]\nscenario = "rt-hexapod"\n', "realtime only"),
    ('[campaign]\nscenario = "sha-step"\ncolour = 1\n', "campaign.colour"),
    (GOOD + "[gird]\n", "gird"),
    (GOOD + "load_kg = [0.0, 99.0]\n", "grid.load_kg"),
    (GOOD + "position_mm = [300.0]\n", "grid.position_mm"),
    (GOOD + "supply_bar = []\n", "grid.supply_bar"),
    (GOOD + "seed = [1.5]\n", "grid.seed"),
    ('[campaign]\nscenario = "sha-step"\n[grid]\ncontroller = ["model-based"]\n', "model-based"),
    ('[campaign]\nscenario = "pm-circle"\n[grid]\nload_kg = [3.0]\n', "grid.load_kg"),
    (GOOD + "[grid.scale]\nviscosity = [1.1]\n", "grid.scale.viscosity"),
    (GOOD + "[montecarlo]\ndraws = 2\n[montecarlo.scale]\nleakage = 1.5\n", "montecarlo.scale.leakage"),
    (GOOD + "[montecarlo.scale]\nleakage = 0.2\n", "montecarlo.draws"),
    (GOOD + "[emulator_config.chambers]\noil_bulk_modulus_bar = -1.0\n", "oil_bulk_modulus_bar"),
    (GOOD + "[controller_config.nope]\nx = 1\n", "nope"),
    ("[campaign\n", "not valid TOML"),
    ('[campaign]\nscenario = "pm-circle"\ncompare = "design-robustness"\n', "campaign.compare"),
    (GOOD + '[grid.controller_config]\n"pi.kp_v_mm" = [500.0]\n', "grid.controller_config.pi.kp_v_mm"),
    (GOOD + '[grid.emulator_config]\n"valve" = [1.0]\n', "grid.emulator_config.valve"),
    (GOOD + 'fault = ["", "LEAK:1:3"]\n', "grid.fault"),
])
def test_a_bad_spec_is_one_line_and_exit_2_before_anything_runs(text, culprit, tmp_path, capsys):
    code = main(["campaign", "run", str(_spec(tmp_path, text)), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and culprit in err[0] and "Traceback" not in err[0], err
    assert not (tmp_path / "out" / "runs").exists()


def test_the_shipped_specs_check_and_count_their_runs(capsys):
    assert main(["campaign", "check", str(SMOKE)]) == 0
    assert "2 runs" in capsys.readouterr().out
    robustness = load_campaign(ROBUSTNESS)
    runs = robustness.runs()
    assert len(runs) == 11 * 3 * 2 * 2                       # Table A.3's 33 points x 2 controllers x 2 draws
    assert len({r.run_id for r in runs}) == len(runs)
    assert [r.params for r in load_campaign(ROBUSTNESS).runs()] == [r.params for r in runs]   # seeded draws
    factors = [r.params[f"scale.{g}"] for r in runs for g in ("stiffness", "leakage", "flow_gain")]
    assert min(factors) >= 0.8 and max(factors) <= 1.2 and len(set(factors)) > 100


@pytest.mark.parametrize("table", ['"pi.kp_v_mm" = [0.06, 0.085]', "pi.kp_v_mm = [0.06, 0.085]"])
def test_a_grid_over_a_config_key_gives_each_run_its_value(table, tmp_path):
    from hil.campaign.engine import tasks
    campaign = load_campaign(_spec(tmp_path, GOOD + "[grid.controller_config]\n" + table + "\n"
                                   "[grid.emulator_config]\n\"valve.spool_time_constant_ms\" = [3.0]\n"))
    runs = tasks(campaign, tmp_path / "out")
    assert sorted(t["controller_config"]["pi"]["kp_v_mm"] for t in runs) == [0.06, 0.085]
    assert all(t["emulator_config"]["valve"]["spool_time_constant_ms"] == 3.0 for t in runs)


def test_a_runs_emulator_sections_scale_the_nominal_plant():
    from plant_emulator.params import load_raw
    nominal = load_raw(None, None)
    campaign = load_campaign(SMOKE)
    params = {"controller": "pi", "scale.stiffness": 1.1, "scale.flow_gain": 0.9, "supply_bar": 30.0, "noise": 2.0}
    sections = campaign.emulator_sections(params, nominal)
    for section, key in SCALES["stiffness"]:
        assert sections[section][key] == pytest.approx(1.1 * nominal[section][key])
    assert sections["valve"]["edge_flow_l_min"] == pytest.approx(0.9 * nominal["valve"]["edge_flow_l_min"])
    assert sections["actuator"]["supply_pressure_bar"] == 30.0
    assert sections["sensors"]["load_cell_noise_n"] == pytest.approx(2.0 * nominal["sensors"]["load_cell_noise_n"])
    load_raw(None, sections)                                 # the emulator takes them


def test_a_fault_in_the_grid_reaches_the_run_command(tmp_path):
    from hil.campaign.engine import tasks
    from hil.campaign.execute import command
    campaign = load_campaign(_spec(tmp_path, GOOD + 'fault = ["", "SEAL_LEAK:1:10"]\n'))
    argvs = [command(t, tmp_path) for t in tasks(campaign, tmp_path / "out")]
    assert ["--inject" in a for a in argvs] == [False, True]
    assert argvs[1][argvs[1].index("--inject") + 1] == "SEAL_LEAK:1:10"


def test_metrics_flatten_without_the_controllers_level():
    doc = {"metrics": {"summary": {"pi": {"overshoot_pct_max": 20.0, "steps": 1}}},
           "checks": [{"name": "PI overshoot", "passed": True}]}
    assert flatten_metrics(doc, "pi") == {"metric.overshoot_pct_max": 20.0, "metric.steps": 1.0,
                                          "check.PI overshoot": True}


def test_the_controllers_summaries_reach_the_row():
    """Faults and the monitors' peaks, the worst of the run's controllers: what a false-alarm
    campaign reads."""
    doc = {"metrics": {}, "children": {
        "controller-pi": {"summary": {"faults": 0, "residual_peak": 0.4, "supply_peak": 0.01}},
        "controller-adaptive": {"summary": {"faults": 1, "residual_peak": 0.6, "supply_peak": 0.02}},
        "emulator": {"summary": {"faults": 7}}}}
    assert flatten_metrics(doc, None) == {"metric.controller.faults": 1.0, "metric.controller.residual_peak": 0.6,
                                          "metric.controller.supply_peak": 0.02}


def test_a_time_scale_reaches_the_pm_runs_only(tmp_path):
    from hil.campaign.engine import tasks
    from hil.campaign.execute import command
    campaign = load_campaign(_spec(tmp_path, '[campaign]\nscenario = "pm-circle"\n[grid]\ntime_scale = [2.0]\n'
                                             'payload_kg = [3.0]\n'))
    task = tasks(campaign, tmp_path / "out")[0]
    argv = command(task, tmp_path)
    assert argv[argv.index("--time-scale") + 1] == "2.0"
    planned = load_campaign(_spec(tmp_path, '[campaign]\nscenario = "pm-circle"\n[grid]\ntime_scale = ["fit"]\n'))
    argv = command(tasks(planned, tmp_path / "out")[0], tmp_path)
    assert argv[argv.index("--time-scale") + 1] == "fit"
    assert task["controller_config"]["hexapod"]["payload_kg"] == 3.0 == task["emulator_config"]["hexapod"]["payload_kg"]
    with pytest.raises(SpecError, match="grid.time_scale"):
        load_campaign(_spec(tmp_path, GOOD + "time_scale = [2.0]\n"))


def test_a_supply_in_the_grid_is_the_controllers_model_supply_too(tmp_path):
    campaign = load_campaign(_spec(tmp_path, GOOD + "supply_bar = [20.0, 40.0]\n"))
    runs = campaign.runs()
    assert [campaign.controller_sections(r.params)["hydraulic_model"]["supply_pressure_bar"] for r in runs] == [20, 40]
    told = load_campaign(_spec(tmp_path, GOOD + 'supply_bar = [20.0]\n[grid.controller_config]\n'
                                                '"hydraulic_model.supply_pressure_bar" = [25.0]\n'))
    assert told.controller_sections(told.runs()[0].params)["hydraulic_model"]["supply_pressure_bar"] == 25.0


def test_how_well_the_plant_is_known_is_the_monitors_too(tmp_path):
    """A flow gain drawn wider than the monitors' spread, and the sensors' noise, are
    declared to the controller's residuals; a narrower draw leaves Table A.3's spread."""
    wide = load_campaign(_spec(tmp_path, GOOD + "noise = [2.0]\n[montecarlo]\ndraws = 1\nseed = 1\n"
                                             "[montecarlo.scale]\nflow_gain = 0.2\n"))
    residuals = wide.controller_sections(wide.runs()[0].params)["residuals"]
    assert residuals == {"flow_spread_pct": pytest.approx(20.0), "pressure_noise_bar": pytest.approx(0.04),
                         "load_cell_noise_n": pytest.approx(0.6)}
    narrow = load_campaign(_spec(tmp_path, GOOD + "[montecarlo]\ndraws = 1\nseed = 1\n"
                                               "[montecarlo.scale]\nflow_gain = 0.05\n"))
    assert "residuals" not in narrow.controller_sections(narrow.runs()[0].params)


def _table(out: Path) -> list[dict]:
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert pcsv.read_csv(out / "results.csv").num_rows == len(rows)
    return rows


@pytest.mark.hil
def test_the_smoke_campaign_on_a_local_cluster_of_two_workers_and_resume(tmp_path):
    out = tmp_path / "smoke"
    proc = hydrapod("campaign", "run", SMOKE, "--workers", "2", "--out", out, "--json")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    summary = json.loads(proc.stdout)
    assert summary["runs"] == summary["ok"] == 2 and summary["workers"] == 2
    rows = _table(out)
    assert len(rows) == 2 and all(r["status"] == "ok" and r["passed"] for r in rows)
    assert {r["param.controller"] for r in rows} == {"pi", "adaptive"}
    assert all(r["metric.overshoot_pct_max"] > 0 and Path(r["out_dir"], "run", "metrics.json").is_file()
               for r in rows)
    # each run on its own plant: the emulator config it was given
    assert len({Path(r["out_dir"], "emulator-overrides.toml").read_text() for r in rows}) == 2
    report = (out / "report.md").read_text()
    assert "the linear loop on Table A.3's plants" in report and list(out.glob("dist_*.png"))
    again = hydrapod("campaign", "run", SMOKE, "--out", out, "--resume", "--json")
    assert again.returncode == 0, again.stderr[-2000:]
    resumed = json.loads(again.stdout)
    assert resumed["ran"] == 0 and resumed["skipped"] == 2 and len(_table(out)) == 2
    refused = hydrapod("campaign", "run", SMOKE, "--out", out)
    assert refused.returncode == 2 and "--resume" in refused.stderr


def _start(argv: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(argv, stdout=open(log, "w"), stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True)


@pytest.mark.hil
def test_the_smoke_campaign_on_a_dask_scheduler_survives_a_killed_worker(tmp_path):
    """`dask scheduler` and two `dask worker` processes on localhost; one worker is killed
    (SIGKILL) once runs are under way: its run is re-queued on the other and completes."""
    scheduler_file = tmp_path / "scheduler.json"
    procs = [_start([str(BIN / "dask"), "scheduler", "--scheduler-file", str(scheduler_file), "--port", "0",
                     "--host", "127.0.0.1", "--no-dashboard"], tmp_path / "scheduler.log")]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        for k in range(2):
            procs.append(_start([str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                 "--no-dashboard", "--name", f"w{k}"], tmp_path / f"worker{k}.log"))
        out = tmp_path / "smoke"
        campaign = subprocess.Popen([str(BIN / "hydrapod"), "campaign", "run", str(SMOKE), "--scheduler", address,
                                     "--out", str(out), "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True, cwd=ROOT)
        # both workers busy: each has an attempt directory of a run under way
        deadline = time.monotonic() + 120
        while len(list(out.glob("runs/*/attempt-0"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(list(out.glob("runs/*/attempt-0"))) >= 2, (tmp_path / "worker0.log").read_text()[-2000:]
        os.killpg(procs[1].pid, signal.SIGKILL)             # the worker (its nanny and process) dies
        stdout, stderr = campaign.communicate(timeout=600)
        assert campaign.returncode == 0, stdout[-2000:] + stderr[-3000:]
        rows = _table(out)
        assert len(rows) == 2 and all(r["status"] == "ok" for r in rows), [(r["status"], r["reason"]) for r in rows]
        assert any(r["attempt"] >= 1 for r in rows)          # the killed worker's run ran again
    finally:
        for proc in procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in procs:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)


def test_the_linear_step_prediction_matches_an_ode_integration_of_the_loop():
    """`design robustness`'s step on a plant (scipy.signal on T = L/(1+L)) against the same
    loop integrated as ODEs: y''' = -b1 y'' - b0 y' + k01 b0 u, u = Kp e + Ki (integral of e)."""
    from scipy.integrate import solve_ivp

    from hil.design.plants import table_a3_plants
    from hil.design.robustness import step_on_plant
    from hil.metrics import step_response
    plant = table_a3_plants()[5]
    kp, ki, step = 0.085e3, 0.46e3, 0.010

    def loop(_, s):
        x, v, a, z = s
        u = kp * (step - x) + ki * z
        return [v, a, -plant.b1 * a - plant.b0 * v + plant.k01 * plant.b0 * u, step - x]

    t = np.linspace(0.0, 3.0, 3001)
    y = solve_ivp(loop, (0.0, 3.0), [0.0, 0.0, 0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-12).y[0]
    ode = step_response(t, y, 0.0, step)
    linear = step_on_plant(plant, kp, ki)
    assert linear["overshoot_pct"] == pytest.approx(ode["overshoot_pct"], abs=0.05)
    assert linear["settling_s"] == pytest.approx(ode["settling_s"], abs=0.002)


@pytest.mark.parametrize(("missing", "status", "attempts"), [([3.0, 0.0], "ok", 2), ([2.0] * 5, "spoiled", 3),
                                                             ([0.0], "ok", 1)])
def test_a_lockstep_run_whose_frames_missed_their_window_runs_again(monkeypatch, missing, status, attempts):
    """Frames that missed the controller's lockstep window mean the machine was too loaded
    for lockstep: the run's faults are not the plant's. It runs again, then is spoiled."""
    import hil.campaign.execute as execute
    calls = []

    def attempt(task):
        calls.append(1)
        return {"run_id": "x", "out_dir": f"a{len(calls)}", "status": "ok", "passed": True, "reason": "",
                "metric.controller.missing_frames": missing[len(calls) - 1]}

    monkeypatch.setattr(execute, "_run_attempt", attempt)
    row = execute.run_one({})
    assert len(calls) == attempts and row["spoiled_attempts"] == attempts - (status == "ok")
    assert row["status"] == status
