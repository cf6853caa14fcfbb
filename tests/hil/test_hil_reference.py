"""The reference the HIL analysis rebuilds from a log equals the controller's own, cycle by
cycle: a move started at once, a step queued to start when it ends, then a multi-point
trajectory queued the same way (the rules of firmware_py/motion_control/reference.py and waypoints.py)."""

import numpy as np

from hil.logdata import Event, LogData, Series
from hil.reference_rebuild import rebuild
from protocol.enums import Ack, AckKind, Command, WaypointFlag
from tests.support.loops import bus_loop, send_waypoint


def _events(cycle, seq, z, segment, accel, flags, result):
    return [Event(cycle, 0.0, "HOST_WAYPOINT_POS", {"TAG": seq & 15, "X": 0.0, "Y": 0.0, "Z": z}),
            Event(cycle, 0.0, "HOST_WAYPOINT_ROT", {"TAG": seq & 15, "ROLL": 0.0, "PITCH": 0.0, "YAW": 0.0}),
            Event(cycle, 0.0, "HOST_WAYPOINT_TIME", {"TAG": seq & 15, "SEQ": seq, "SEGMENT_TIME": segment,
                                                     "ACCEL_TIME": accel, "FLAGS": flags}),
            Event(cycle, 0.0, "CTRL_ACK", {"KIND": AckKind.WAYPOINT, "SEQ": seq, "RESULT": int(result),
                                           "QUEUE_FREE": 0})]


def test_rebuilt_reference_equals_the_controllers():
    loop, ctl, bus = bus_loop("testbench", "pi")
    period = loop.period_s
    plan = {                 # cycle -> waypoints sent before that cycle's update (seq, z, segment, accel, flags)
        20: [(0, 0.160, 0.001 * 500, 0.001 * 100, WaypointFlag.LAST | WaypointFlag.START)],
        120: [(1, 0.170, 0.001 * 300, 0.001 * 150, WaypointFlag.LAST | WaypointFlag.START | WaypointFlag.STEP)],
        130: [(2, 0.180, 0.001 * 250, 0.001 * 50, WaypointFlag.START),
              (3, 0.150, 0.001 * 370, 0.001 * 100, WaypointFlag.LAST)],
    }
    events, yr, initial = [], [], None
    for cycle in range(900):
        for seq, z, segment, accel, flags in plan.get(cycle, []):
            if initial is None:
                initial = ctl.status.reference_m.copy()
            result = send_waypoint(ctl, seq, 0.0, 0.0, z, segment=segment, accel=accel, flags=flags)
            assert result is Ack.ACCEPTED
            events += _events(cycle, seq, z, segment, accel, flags, result)
        loop.cycle()
        yr.append(ctl.status.reference_m[0])
    n = len(yr)
    log = LogData("synthetic", n, np.zeros(n), {"LEG_STATE_1": Series(
        "LEG_STATE_1", np.arange(n), np.zeros(n), np.full((n, 6), 0.15), {"POSITION": 4})}, events, 0, {}, {}, 0)
    ref = rebuild(log, "testbench", period, initial_position=initial)
    assert [m.seqs for m in ref.motions] == [[0], [1], [2, 3]]
    assert ref.motions[1].step
    rebuilt = ref.yr[20:, 0]
    assert np.isfinite(rebuilt).all()
    np.testing.assert_array_equal(rebuilt, np.array(yr[20:]))


def test_rebuilt_reference_of_a_host_start_equals_the_controllers():
    """A waypoint queued without START, then HOST_CMD START through the host link: carried out
    in the next update, its trajectory's clock is the rule's (t = T in that cycle)."""
    loop, ctl, bus = bus_loop("testbench", "pi")
    events, yr = [], []
    initial = ctl.status.reference_m.copy()
    for cycle in range(400):
        if cycle == 10:
            assert send_waypoint(ctl, 0, 0.0, 0.0, 0.170, segment=0.4, accel=0.1,
                                 flags=WaypointFlag.LAST) is Ack.ACCEPTED
            events += _events(cycle, 0, 0.170, 0.4, 0.1, WaypointFlag.LAST, Ack.ACCEPTED)
        if cycle == 30:
            ctl.host.command(int(Command.START), 0, 7)          # as the loop queues a received frame
            events += [Event(cycle, 0.0, "HOST_CMD", {"COMMAND": int(Command.START), "ARGUMENT": 0, "SEQ": 7}),
                       Event(cycle, 0.0, "CTRL_ACK", {"KIND": AckKind.HOST_CMD, "SEQ": 7,
                                                      "RESULT": int(Ack.ACCEPTED), "QUEUE_FREE": 0})]
        loop.cycle()
        yr.append(ctl.status.reference_m[0])
    n = len(yr)
    log = LogData("synthetic", n, np.zeros(n), {"LEG_STATE_1": Series(
        "LEG_STATE_1", np.arange(n), np.zeros(n), np.full((n, 6), 0.15), {"POSITION": 4})}, events, 0, {}, {}, 0)
    ref = rebuild(log, "testbench", loop.period_s, initial_position=initial)
    assert [m.seqs for m in ref.motions] == [[0]]
    np.testing.assert_array_equal(ref.yr[30:, 0], np.array(yr[30:]))


def test_sha_tracking_reports_a_sweep_whose_light_load_at_the_lowest_w_was_cut(monkeypatch):
    """A fault cut the lightest load's run at the lowest w (it is not in the log's runs): the
    analysis judges the lowest w's lightest run it has instead of failing with an exception."""
    import hil.scenarios.sha_tracking as sha_tracking
    from hil.scenarios import SCENARIOS

    def run(controller, load, w, error):
        return {"controller": controller, "load_kg": load, "w_rad_s": w, "max_error_mm": error,
                "rms_error_mm": error / 2, "reference_vs_sine_mm": 0.0, "fault": 0}

    runs = [run("pi", 0.0, 0.5, 3.0), run("pi", 3.0, 0.1, 1.0), run("pi", 6.0, 0.1, 1.2)]
    monkeypatch.setattr(sha_tracking, "sine_runs", lambda log, period: runs)
    monkeypatch.setattr(sha_tracking, "refused_sines", lambda log: [])
    analysis = SCENARIOS["sha-tracking"].analyze(None, None)
    light = next(c for c in analysis.checks if c.name.startswith("pi: rms error at the lowest w (0.1 rad/s)"))
    assert light.name.endswith("3 kg") and light.measured == "0.50 mm"


def test_an_analysis_models_the_plant_its_run_emulated(tmp_path):
    """The emulator.toml the runner writes beside the log (payload, plant) is the analyses'
    plant; a log without one gets the defaults."""
    from hil.scenarios.common import run_emulator_config
    from plant_emulator.params import load_config
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "emulator.toml").write_text("[hexapod]\npayload_kg = 6.0\n[actuator]\n"
                                                    "supply_pressure_bar = 40.0\n")

    def log_at(path):
        return LogData(str(path), 0, np.zeros(0), {}, [], 0, {}, {}, 0)
    ran = run_emulator_config(log_at(tmp_path / "run" / "run.blf"))
    assert ran.hexapod.payload_kg == 6.0 and ran.actuator.supply_pressure_pa == 40e5
    default = run_emulator_config(log_at(tmp_path / "run.blf"))
    assert default.hexapod.payload_kg == load_config().hexapod.payload_kg == 0.0
    assert default.actuator.supply_pressure_pa == load_config().actuator.supply_pressure_pa


def test_sha_tracking_names_a_sine_refused_as_beyond_capacity_with_the_timing_that_fits():
    """The sweep goes on past a refused sine (nothing moved); the analysis finds it in the log:
    its w from the refused waypoint's SEGMENT_TIME, the timing from the acknowledgement."""
    from hil.scenarios.sha_tracking import POINTS_PER_PERIOD, refused_sines
    from protocol.enums import EmuCommand, time_scale_to_wire
    tm = 2 * np.pi / 9.8 / POINTS_PER_PERIOD
    events = [Event(0, 0.0, "EMU_CTRL", {"COMMAND": int(EmuCommand.SET_LOAD), "TARGET": 0, "FAULT": 0,
                                         "LOAD_MASS": 3.0, "FAULT_PARAM": 0})]
    events += _events(5, 40, 0.1, tm, tm / 2, 0, Ack.ACCEPTED)[:3]
    events.append(Event(5, 0.0, "CTRL_ACK", {"KIND": AckKind.WAYPOINT, "SEQ": 40, "RESULT": int(Ack.BEYOND_CAPACITY),
                                             "QUEUE_FREE": 0, "TIME_SCALE": time_scale_to_wire(1.1)}))
    status = Series("CTRL_STATUS", np.array([0]), np.zeros(1), np.array([[0.0]]), {"CONTROLLER": 0})
    log = LogData("synthetic", 10, np.zeros(10), {"CTRL_STATUS": status}, events, 0, {}, {}, 0)
    assert refused_sines(log) == [{"controller": "pi", "load_kg": 3.0, "w_rad_s": 9.8, "time_scale_fits": 1.1}]
