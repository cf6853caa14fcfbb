"""The cycle budget: each phase of the controller's cycle and of the emulator's SYNC handling
is timed where it happens (a phase made slow shows up in that phase alone), and the report
and `hil run --profile` print the table from the processes' summaries."""

from __future__ import annotations

from firmware_py.config import load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime.loop import PHASES, ControllerLoop
from hil.report import format_budget
from plant_emulator.emulator import SYNC_PHASES, Emulator
from plant_emulator.loopback_bus import LoopbackBus
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.process import run
from plant_emulator.rigs import make_rig
from tests.support.buses import ScriptedBus, sync_frame

TICK_S = 1e-6


class TickingClock:
    """Each reading advances 1 us; `spend(s)` stands for work that takes s."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        self.now += TICK_S
        return self.now

    def spend(self, seconds: float) -> None:
        self.now += seconds


def test_the_controller_loop_times_each_phase_where_it_happens():
    ctl = Controller(load_config(), "testbench", 0.002, CONTROLLER_NAMES["pi"])
    emulator = load_emulator_config()
    bus = LoopbackBus(make_rig("testbench", emulator), emulator)
    clock = TickingClock()
    loop = ControllerLoop(bus, ctl, 500.0, "lockstep", clock=clock, log=lambda _: None)
    loop.activate()
    update, after_write = ctl.update, ctl.after_write

    def slow_update(meas, cmd):
        clock.spend(200e-6)
        update(meas, cmd)

    def slow_host_work(time_left_s, clock_=None):
        clock.spend(50e-6)
        after_write(time_left_s, clock_)

    ctl.update, ctl.after_write = slow_update, slow_host_work
    for _ in range(200):
        loop.cycle()
    phases = loop.timing()["phases_us"]
    assert list(phases) == list(PHASES)
    assert 200.0 <= phases["update"]["p50"] < 215.0, phases["update"]
    assert 50.0 <= phases["host_work"]["p50"] < 60.0, phases["host_work"]
    assert phases["decode"]["p50"] > 0.0                     # the LEG_STATEs were handled in the window
    for quick in ("sync", "read", "write"):
        assert phases[quick]["p99"] < 50.0, (quick, phases[quick])
    # the phases of one cycle add up to its length from SYNC to SYNC
    k = (loop.stats.cycles - 2) % len(loop.phase_s)
    total = loop.phase_s[k, :-1].sum() + loop.phase_s[k + 1, -1]
    assert total > 250e-6


def test_the_emulator_times_its_physics_apart_from_its_response():
    cfg = load_emulator_config()
    bus = ScriptedBus([("frame", sync_frame(k)) for k in range(1, 101)])
    clock = TickingClock()
    emulator = Emulator(bus, make_rig("testbench", cfg), cfg, clock=clock)
    advance = emulator.rig.advance

    def slow_physics(seconds):
        clock.spend(300e-6)
        advance(seconds)

    emulator.rig.advance = slow_physics
    run(emulator, bus, lambda: not bus.script)
    phases = emulator.summary()["phases_us"]
    assert list(phases) == list(SYNC_PHASES)
    assert 300.0 <= phases["physics"]["p50"] < 310.0, phases["physics"]
    assert phases["response"]["p99"] < 50.0, phases["response"]   # frames go out before the physics
    assert phases["total"]["p50"] >= phases["physics"]["p50"] + phases["response"]["p50"] - 1.0


def test_the_budget_table_has_a_row_per_process_and_phase():
    p = {"p50": 1.0, "p99": 2.0, "max": 3.0}
    doc = {"rate_hz": 500.0, "children": {
        "emulator": {"summary": {"phases_us": {name: p for name in SYNC_PHASES}}},
        "controller": {"summary": {"timing": {"phases_us": {name: p for name in PHASES}}}},
        "recorder": {"summary": None}}}
    table = format_budget(doc)
    assert "period 2000 us" in table
    rows = [line for line in table.splitlines() if line.startswith("| emulator") or line.startswith("| controller")]
    assert len(rows) == len(SYNC_PHASES) + len(PHASES)
    assert "| controller | update | 1 | 2 | 3 |" in rows
    assert format_budget({"children": {}}) == ""


def test_a_realtime_run_says_in_one_line_whether_it_was_clean():
    from hil.report import realtime_line
    timing = {"period_error_us": {"p99": 60.0, "max": 900.0}, "compute_time_us": {"p99": 400.0, "max": 1000.0}}
    doc = {"pacing": "realtime", "overruns": 0, "ctrl_status_timing": timing,
           "children": {"emulator": {"summary": {"host_stalls": 0, "host_stall_max_ms": 0.0}}}}
    assert realtime_line(doc).startswith("realtime: clean: overruns 0, period error p99 60.0 us")
    doc["children"]["emulator"]["summary"]["host_stalls"] = 2
    assert realtime_line(doc).startswith("realtime: NOT clean") and "emulator stalls 2" in realtime_line(doc)
    doc["children"]["emulator"]["summary"]["host_stalls"] = 0
    doc["overruns"] = 1
    assert "NOT clean: overruns 1" in realtime_line(doc)
    assert realtime_line({**doc, "pacing": "lockstep"}) == ""
