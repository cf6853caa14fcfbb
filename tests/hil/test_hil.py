"""HIL runner end to end: `hydrapod hil run sha-step --short` starts the emulator and the
controller as processes on a fresh multicast bus, records a BLF log, and the metrics come
from that log; stock tools (cantools, python-can's reader) decode the same log."""

import json

import can
import cantools
import pytest

from firmware_py.supervision.diagnostics import PEAK_KEYS
from hil.logdata import frames_by_sender, frames_counted_by_senders, read_log
from hil.scenarios.sha_classical import KD_V_S_MM, LOOPS
from physics.constants import MM
from protocol.dbc import dbc_path
from tests.support.cli import hydrapod, reanalysed

CONTROLLERS = ("pi", "adaptive", "computed-torque")     # sha-step and sha-tracking run all three

# the tests reading the one run share a worker (make test distributes with --dist loadgroup)
SHA_STEP_GROUP = pytest.mark.xdist_group("sha-step-run")


FALSE_ALARM_MARGIN = 1.5        # the actuators' residuals stay below 1 / 1.5 of their thresholds


def assert_false_alarm_margin(doc: dict) -> None:
    """Every controller of a no-fault run kept its residuals and its supply samples below
    1 / FALSE_ALARM_MARGIN of their thresholds (its summary's `residual_peak`, `supply_peak`,
    `spool_peak`, `attitude_peak`, `pressure_peak`)."""
    peaks = {(name, key): child["summary"][key] for name, child in doc["children"].items()
             if name.startswith("controller") for key in PEAK_KEYS}
    assert peaks and all(p * FALSE_ALARM_MARGIN <= 1.0 for p in peaks.values()), peaks


@pytest.fixture(scope="module")
def sha_step_run(tmp_path_factory):
    """One short sha-step run that several tests read."""
    out = tmp_path_factory.mktemp("sha-step")
    return out, hydrapod("hil", "run", "sha-step", "--short", "--out", out, "--json")


@pytest.mark.hil
@SHA_STEP_GROUP
def test_sha_step_short_passes_with_zero_e2e_errors(sha_step_run):
    out, proc = sha_step_run
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    doc = json.loads((out / "metrics.json").read_text())
    assert {"scenario", "passed", "metrics", "thesis", "e2e_errors", "overruns"} <= set(doc)
    assert doc["passed"] and doc["scenario"] == "sha-step"
    assert doc["e2e_errors"] == 0 and doc["log"]["lost_frames"] == 0
    assert doc["failure"] is None
    steps = doc["metrics"]["steps"]
    # 3 controllers x 2 loads x 2 positions, each a square wave +10, -10, +10 mm; the last is measured
    controllers = CONTROLLERS
    assert {s["controller"] for s in steps} == set(controllers) and len(steps) == 36
    assert [round(s["step_mm"]) for s in steps] == [10, -10, 10] * 12
    assert [s["measured"] for s in steps] == [False, False, True] * 12
    assert all(doc["metrics"]["summary"][c]["steps"] == 4 for c in controllers)
    # beyond the thesis: computed torque meets its adaptive claim on every step (< 14 %, <= 1 s)
    ct = {c["name"]: c for c in doc["checks"] if c["name"].startswith("computed-torque")}
    assert len(ct) == 2 and all(c["passed"] and c["required"] for c in ct.values()), ct
    for name in ("emulator", "controller"):
        assert doc["children"][name]["exit_status"] == 0
    assert_false_alarm_margin(doc)
    assert (out / "report.md").read_text().count("thesis") >= 3
    assert (out / "sha_step.png").stat().st_size > 10_000


@pytest.mark.hil
@SHA_STEP_GROUP
def test_analyze_reproduces_the_run_metrics_from_the_log_alone(sha_step_run, tmp_path):
    out, _ = sha_step_run
    again, first = reanalysed(out, "sha-step", tmp_path)
    assert again["metrics"] == first["metrics"]


@pytest.mark.hil
@SHA_STEP_GROUP
def test_the_log_decodes_with_stock_cantools_and_python_can(sha_step_run):
    out, _ = sha_step_run
    db = cantools.database.load_file(str(dbc_path()))
    counts, positions = {}, []
    with can.LogReader(str(out / "run.blf")) as reader:          # python-can's reader (can.player's)
        for msg in reader:
            counts[msg.arbitration_id] = counts.get(msg.arbitration_id, 0) + 1
            if msg.arbitration_id == db.get_message_by_name("LEG_STATE_1").frame_id:
                positions.append(db.decode_message(msg.arbitration_id, msg.data)["POSITION"])
    log = read_log(out / "run.blf")
    assert sum(counts.values()) == log.frames
    assert len(positions) == len(log.get("LEG_STATE_1"))
    # cantools (mm) and the project's codec (m) agree frame by frame
    assert max(abs(p / 1000.0 - q) for p, q in zip(positions, log.get("LEG_STATE_1")["POSITION"])) < 1e-9
    assert counts[0x080] == log.n_cycles


@pytest.mark.hil
@SHA_STEP_GROUP
def test_the_log_holds_every_frame_each_sender_sent(sha_step_run):
    """Nothing lost: the BLF holds as many frames of each sender as it counted sending."""
    out, _ = sha_step_run
    doc = json.loads((out / "metrics.json").read_text())
    counts = frames_by_sender(out / "run.blf")
    children = {name: child["summary"] for name, child in doc["children"].items()}
    sent = frames_counted_by_senders(children, doc["frames_sent_by_host"])
    assert counts == sent
    assert min(counts["controller"], counts["emulator"]) > 10_000


@pytest.mark.hil
@SHA_STEP_GROUP
def test_every_cycle_has_its_leg_frame_despite_on_host_reordering(sha_step_run):
    out, _ = sha_step_run
    log = read_log(out / "run.blf")
    cycles = log.get("LEG_STATE_1").cycle
    assert len(set(cycles.tolist())) == len(cycles)        # never two in one cycle


@pytest.mark.hil
@SHA_STEP_GROUP
def test_the_monitor_replays_the_sha_step_log(sha_step_run):
    """`hydrapod monitor --replay` of the run's log ends showing the log's last controller
    state, fault and leg position (stock cantools decoding the same log as the oracle)."""
    from tests.support.monitor import assert_replay_shows_the_log
    out, _ = sha_step_run
    assert_replay_shows_the_log(out / "run.blf")


@pytest.mark.hil
def test_an_injected_fault_lasts_the_whole_experiment(tmp_path):
    """`hil run --inject`: the emulator gets the fault before the script, and says so."""
    proc = hydrapod("hil", "run", "sha-step", "--short", "--controllers", "pi", "--loads", "0", "--positions", "50",
                    "--inject", "SEAL_LEAK:1:10", "--no-plots", "--out", tmp_path, "--json")
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    doc = json.loads(proc.stdout)
    assert any("injected SEAL_LEAK on node 1 (param 10)" in n for n in doc["notes"])
    emulator = json.loads((tmp_path / "emulator.json").read_text())
    assert emulator["injected"].get("SEAL_LEAK", 0) >= 1, emulator["injected"]


@pytest.mark.parametrize("argv, culprit", [
    (["hil", "run", "no-such"], "no-such"),
    (["hil", "run", "sha-step", "--bus", "udp_multicast:10.0.0.1"], "10.0.0.1"),
    (["hil", "run", "sha-step", "--controllers", "pi,fuzzy"], "fuzzy"),
    (["hil", "run", "sha-step", "--controllers", "model-based"], "model-based"),
    (["hil", "run", "pm-circle", "--loads", "3"], "pm-circle"),
    (["hil", "run", "sha-classical", "--controllers", "adaptive"], "adaptive"),
    (["hil", "run", "sha-stick-slip", "--positions", "50"], "sha-stick-slip"),
    (["hil", "run", "guide-free-fall", "--controllers", "adaptive"], "adaptive"),
    (["hil", "run", "pm-circle", "--positions", "50"], "pm-circle"),
    (["hil", "run", "sha-step", "--positions", "50,300"], "300 mm"),
    (["hil", "run", "pm-circle", "--emulator-config", "/nonexistent/plant.toml"], "plant.toml"),
    (["hil", "analyze", "/nonexistent/run.blf", "--scenario", "sha-step"], "run.blf"),
    (["hil", "analyze", "x.txt", "--scenario", "sha-step"], "x.txt"),
    (["hil", "faults", "--payload-kg", "500"], "--payload-kg"),
    (["hil", "run", "sha-step", "--rate-hz", "50"], "--rate-hz"),
    (["hil", "analyze", "x.blf", "--scenario", "sha-step", "--rate-hz", "fast"], "--rate-hz"),
])
def test_cli_errors_are_one_line_and_exit_2(argv, culprit, tmp_path):
    proc = hydrapod(*argv, *(["--out", tmp_path] if argv[1] == "run" else []))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and culprit in lines[0] and "Traceback" not in proc.stderr


def test_list_names_the_scenarios():
    proc = hydrapod("hil", "list", "--json")
    names = {row["name"] for row in json.loads(proc.stdout)}
    assert {"sha-step", "sha-tracking", "sha-perturbation", "pm-diagonal", "pm-circle", "rt-testbench",
            "rt-hexapod", "sha-identification"} <= names


# scenario, arguments, what its metrics must hold (besides passing with a clean bus)
SCENARIO_RUNS = {
    "sha-tracking": (["--short"], lambda m: {(r["controller"], r["load_kg"], round(r["w_rad_s"], 1))
                                            for r in m["runs"]} == {(c, load, w) for c in CONTROLLERS
                                                                    for load in (0.0,) for w in (0.5, 2.0)}),
    # the RLS mass and the load pressure from the log alone (CTRL_LOAD): a segment per load
    "sha-perturbation": ([], lambda m: all(len(r["load_changes"]) == 3 and len(r["estimates"]["segments"]) == 4
                                           for r in m["runs"].values())
                         and set(m["runs"]) == {"pi", "adaptive"}),
    # the thesis's timing. The circle: all three complete, model-based < PI+P is required and
    # computed torque is held to <= 2 x the thesis's IAE and <= 10 mm (measured 4-8 mm). The
    # diagonal's short variant: computed torque alone (the thesis's two fault there)
    "pm-circle": ([], lambda m: set(m["controllers"]) == {"adaptive", "model-based", "computed-torque"}
                  and m["time_scale"] == 1.0 and all(r["complete"] for r in m["controllers"].values())),
    # the modal kick test at home (the full run adds the circle's start): both pushes found,
    # fitted (r2 >= 0.95, a required check) and set beside the sealed model's mode
    "hex-kick": (["--short"], lambda m: [k["axis"] for k in m["kicks"]] == ["X", "Y"]
                 and all(k["model_frequency_hz"] and 2.0 < k["frequency_hz"] < 8.0 for k in m["kicks"])),
    # ... on stock devices at the rate one real bus carries them (PROTOCOL.md "The budget")
    "pm-diagonal": (["--short", "--devices", "canopen", "--rate-hz", "342"],
                    lambda m: set(m["controllers"]) == {"computed-torque"} and m["time_scale"] == 1.0
                    and m["controllers"]["computed-torque"]["complete"]
                    and max(m["controllers"]["computed-torque"]["max_error_truth_mm"].values()) <= 10.0),
    # realtime pacing, their short 10 s (the full runs are 60 s; the soak runs a minute): jitter,
    # overruns and faults after a machine stall are reported; asserted: ran the time, no fault
    # without a stall before it. Their timing figures are benchmarks (docs/MEASUREMENTS.md).
    "rt-testbench": (["--short"], lambda m: m["seconds"] >= 9.5
                     and set(m["sync_interval_error_us"]) >= {"p50", "p99", "max"}),
    "rt-hexapod": (["--short"], lambda m: m["seconds"] >= 9.5
                   and set(m["ctrl_status"]["period_error_us"]) >= {"p50", "p99", "max"}),
    # the loop of each step identified from the log: the D term the controller applied is the one configured
    "sha-classical": (["--short"], lambda m: {(r["loop"], r["load_kg"]) for r in m["steps"]}
                      == {(loop, 6.0) for loop in LOOPS}
                      and all(abs(r["kd"] * MM / KD_V_S_MM - 1.0) < 0.05 for r in m["steps"] if "d" in r["loop"])),
    # the short variant: 6 kg, a ramp inside the Stribeck region (cycles) and one above it (none)
    "sha-stick-slip": (["--short"], lambda m: {(r["load_kg"], r["speed_mm_s"], r["cycling"]) for r in m["ramps"]}
                       == {(6.0, 8.0, True), (6.0, 20.0, False)}),
    # Appendix D: a fall at 0 and at 6 kg, eq. D.4's Fc and sigma_v against the emulator's guide
    "guide-free-fall": (["--short"], lambda m: [r["load_kg"] for r in m["loads"]] == [0.0, 6.0] and m["falls"] == 2),
    # every point's Kx, Kd, Kp (eq. 5.8-5.10) and load path (eq. 5.11) beside the linearisation's
    "sha-identification": (["--short"], lambda m: (
        {(r["set_point_mm"], r["load_kg"], tuple(r["gains_v_mm"])) for r in m["points"]}
        == {(p, load, (0.25, 0.3)) for p in (60.0, 210.0) for load in (0.0, 6.0)}
        and all(r["sensibilities"]["kx"] > 0 and r["sensibilities"]["kd"] > 0 and r["sensibilities"]["kp"] < 0
                and r["emulator"]["kx"] > 0 for r in m["points"])
        # chapter 5.2.4's refinement on the complete model, every window judged against G(s) alone
        and all(r["complete"]["windows"] == r["windows"] and 0 <= r["complete"]["at_least_g"] <= r["windows"]
                and r["complete"]["kx"] > 0 for r in m["points"])
        # Fig. 5.10's table per load (two set points: no interior point to judge)
        and set(m["scheduled"]["loads"]) == {"0", "6"} and m["scheduled"]["left_out"] == [])),
}


@pytest.mark.hil
def test_a_power_unit_weaker_than_configured_slows_the_diagonal_instead_of_faulting(tmp_path):
    """Half the pump's flow the controller assumes (5 l/min): the flow runs short on the
    diagonal, the controller slows the reference's clock (CTRL_CLOCK, the analysis's replay
    equal to it) and the movement completes within 10 mm. Without the time scaling the same
    run ends in SUPPLY_PRESSURE, 63-162 mm off its path (docs/MEASUREMENTS.md)."""
    emulator = tmp_path / "pump.toml"
    emulator.write_text("[power_unit]\npump_flow_l_min = 5.0\n")
    proc = hydrapod("hil", "run", "pm-diagonal", "--short", "--out", tmp_path / "run", "--json", "--no-plots",
                    "--emulator-config", emulator)
    doc = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert proc.returncode == 0 and doc["passed"], [c for c in doc["checks"] if not c["passed"]]
    clock, run = doc["metrics"]["clock"], doc["metrics"]["controllers"]["computed-torque"]
    assert clock["frames_checked"] > 50 and clock["mismatches"] == 0
    assert clock["slowest_rate"] < 0.5 and clock["stretched_s"] > 1.0
    assert run["complete"] and max(run["max_error_truth_mm"].values()) <= 10.0


@pytest.mark.parametrize("scenario", [pytest.param(name, marks=pytest.mark.realtime if name.startswith("rt-")
                                                   else pytest.mark.hil) for name in SCENARIO_RUNS])
def test_scenario_runs_from_the_command_and_passes(scenario, tmp_path):
    args, holds = SCENARIO_RUNS[scenario]
    proc = hydrapod("hil", "run", scenario, "--out", tmp_path, "--json", *args)
    assert proc.returncode in (0, 1), proc.stdout[-3000:] + proc.stderr[-3000:]
    doc = json.loads((tmp_path / "metrics.json").read_text())
    failed = [c for c in doc["checks"] if c["required"] and not c["passed"]]
    assert doc["behaviour_passed"] and doc["failure"] is None, failed
    # the exit code is the command's verdict; here only a speed goal may have failed it (a
    # benchmark check: the loop's period error on a shared machine, reported here)
    assert proc.returncode == (0 if doc["passed"] else 1) and all(c["benchmark"] for c in failed), failed
    # sha-step asserts exactly 0; here a rare datagram the on-host multicast dropped under
    # load (seen once in a pm-circle run, 163k frames) must stay rare and be counted
    # (sha-identification restarts the controller per gain: the log reader takes a new
    # controller's counters afresh at its NMT start, so that adds no error either)
    assert doc["e2e_errors"] <= 1e-4 * doc["log"]["frames"], doc["e2e_errors"]
    assert doc["log"]["lost_frames"] == 0
    assert holds(doc["metrics"]), doc["metrics"]
    assert doc["rate_hz"] == (342.0 if "--rate-hz" in args else 500.0)
    assert_false_alarm_margin(doc)
    assert list(tmp_path.glob("*.png")) and "thesis" in (tmp_path / "report.md").read_text()

