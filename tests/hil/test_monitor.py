"""`hydrapod monitor`: the view decodes what the bus carries (E2E-checked), the screen shows
it, a replayed log reads like the live bus did, --control reaches the controller, and bad
input is one line and exit 2."""

from __future__ import annotations

import asyncio
import csv
import json
import os
import subprocess
import sys
import time

import can
import cantools
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.cli import main
from hil.monitor.app import MonitorApp
from hil.monitor.sources import CommandSender, LiveSource
from hil.monitor.view import BusView
from protocol.bus import open_bus
from protocol.codec import CODECS
from protocol.dbc import dbc_path
from protocol.enums import Command, EmcyCode, EmuCommand, EmuFault, Fault, NmtState, State, ValveState
from protocol.outbox import Outbox
from tests.support.buses import GROUP, free_port
from tests.support.monitor import assert_replay_shows_the_log, replay, text_of

PERIOD_S = 0.002


class Frames:
    """Frames as their senders would encode them (one alive counter per message)."""

    def __init__(self):
        self.boxes: dict[str, Outbox] = {}

    def __call__(self, name: str, **values) -> bytes:
        box = self.boxes.setdefault(name, Outbox(name))
        for key, value in values.items():
            box.values[box.index[key]] = value
        assert box.encode()
        return bytes(box.message.data)


def _cycle(view: BusView, frames: Frames, t: float, k: int, positions_m, forces_n) -> None:
    view.feed(t, CODECS["SYNC"].frame_id, frames("SYNC", COUNTER=k % 240 + 1))
    for leg, (x, f) in enumerate(zip(positions_m, forces_n, strict=True)):
        view.feed(t + 2e-4, CODECS[f"LEG_STATE_{leg + 1}"].frame_id,
                  frames(f"LEG_STATE_{leg + 1}", POSITION=x, FORCE=f, VALVE_STATE=int(ValveState.ACTIVE)))
        view.feed(t + 4e-4, CODECS[f"VALVE_CMD_{leg + 1}"].frame_id,
                  frames(f"VALVE_CMD_{leg + 1}", CW_D=1, CW_H=0, CW_M=1, CW_R=0, SPOOL_SETPOINT=0.01 * (leg + 1)))


def test_the_view_shows_what_the_frames_say():
    view, frames = BusView(), Frames()
    positions = np.linspace(0.10, 0.15, 6)
    for k in range(600):                                  # 1.2 s of a six-leg bus, one late SYNC
        t = k * PERIOD_S + (0.0005 if k == 300 else 0.0)
        _cycle(view, frames, t, k, positions + 1e-4 * k, np.full(6, 50.0))
    t = 600 * PERIOD_S
    view.feed(t, CODECS["CTRL_STATUS"].frame_id,
              frames("CTRL_STATUS", STATE=int(State.FAULT), FAULT_CODE=int(Fault.ACTUATOR_RESIDUAL),
                     ACTIVE_WAYPOINT=7, OVERRUNS=2))
    view.feed(t, CODECS["EMCY_16"].frame_id,
              frames("EMCY_16", ERROR_CODE=int(EmcyCode.CONTROL_DEVIATION), DETAIL=int(Fault.ACTUATOR_RESIDUAL),
                     INFO=3))
    view.feed(t, CODECS["HEARTBEAT_2"].frame_id, frames("HEARTBEAT_2", STATE=int(NmtState.OPERATIONAL)))
    view.feed(t, CODECS["CTRL_PAYLOAD"].frame_id, frames("CTRL_PAYLOAD", ESTIMATING=1, MASS=2.5))
    view.feed(t, CODECS["CTRL_LOAD"].frame_id,
              frames("CTRL_LOAD", LEG=2, MASS=4.35, LOAD_PRESSURE=7.0e5, FRICTION=-12.0))
    view.feed(t, CODECS["CTRL_CLOCK"].frame_id, frames("CTRL_CLOCK", MOVING=1, SCALED=1, RATE=0.625,
                                                        MOTION_TIME=123.5))
    bad = bytearray(frames("LEG_STATE_2", POSITION=0.2, FORCE=0.0))
    bad[3] ^= 0xFF                                         # a corrupted frame: rejected, not shown
    view.feed(t, CODECS["LEG_STATE_2"].frame_id, bad)

    s = view.snapshot()
    assert (s.state, s.fault, s.fault_leg, s.active_waypoint, s.overruns) == ("FAULT", "ACTUATOR_RESIDUAL", 3, 7, 2)
    assert s.n_legs == 6 and s.legs[1].rejected == 1 and s.rejected == 1 and s.lost == 0
    assert s.legs[1].position_m == pytest.approx(positions[1] + 1e-4 * 599, abs=5e-6)     # not the corrupted 0.2
    assert s.legs[0].velocity_m_s == pytest.approx(1e-4 / PERIOD_S, rel=0.05)
    assert s.legs[2].control_bits == "D-M-" and s.legs[2].spool_cmd == pytest.approx(0.03, abs=1e-4)
    assert s.heartbeats["LEG2"][0] == "OPERATIONAL"
    assert (s.payload_kg, s.payload_estimated, s.clock_rate) == (2.5, True, 0.625)
    assert (s.legs[1].load_mass_kg, s.legs[1].load_pressure_pa) == (pytest.approx(4.35), pytest.approx(7.0e5))
    assert "CONTROL_DEVIATION ACTUATOR_RESIDUAL leg 3" in s.emcy[-1].text
    assert s.sync_period_us == pytest.approx(2000, abs=1)
    assert s.sync_jitter_max_us == pytest.approx(500, abs=1)          # the one late SYNC
    assert s.rates["LEG_STATE_1"] == pytest.approx(500, rel=0.02)
    # each cycle: SYNC 1 byte, 6 x LEG_STATE 7 bytes, 6 x VALVE_CMD 4 bytes, at 500 Hz of 1 Mbit/s
    bits = (8 + 47) + 6 * (56 + 47) + 6 * (32 + 47)
    assert s.load == pytest.approx(bits * 500 / 1e6, rel=0.02)


def test_the_export_writes_the_window_in_thesis_units(tmp_path):
    view, frames = BusView(), Frames()
    for k in range(1000):
        _cycle(view, frames, k * PERIOD_S, k, np.full(6, 0.1 + 1e-5 * k), np.arange(6.0))
    rows = view.export_csv(tmp_path / "w.csv", end_s=999 * PERIOD_S, window_s=0.5)
    with open(tmp_path / "w.csv") as f:
        table = list(csv.DictReader(f))
    assert rows == len(table) == 250
    last = table[-1]
    # a SYNC row holds the frames of the cycle before it
    assert float(last["leg1_position_mm"]) == pytest.approx((0.1 + 1e-5 * 998) * 1e3, abs=0.01)
    assert float(last["leg6_force_n"]) == pytest.approx(5.0, abs=0.05)
    assert float(last["leg3_spool_cmd_pct"]) == pytest.approx(3.0, abs=0.01)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([c.frame_id for c in CODECS.values()] + [0x7FF, 0x123]),
                          st.binary(min_size=0, max_size=8), st.booleans()), max_size=60))
def test_any_bytes_on_the_bus_are_counted_never_raised(frames):
    view = BusView()
    for k, (frame_id, data, extended) in enumerate(frames):
        view.feed(k * 1e-4, frame_id, data, extended)
    s = view.snapshot()
    assert s.frames == len(frames)


class _Peer:
    """Emulator and controller (test bench, lockstep) as processes on a bus of their own."""

    def __init__(self, tmp_path):
        from hil.runner import LOCKSTEP_HEARTBEAT_TIMEOUT_MS
        self.spec = f"udp_multicast:{GROUP}:{free_port()}"
        config = tmp_path / "controller.toml"
        config.write_text(f"[timing]\nheartbeat_timeout_ms = {LOCKSTEP_HEARTBEAT_TIMEOUT_MS}\n")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.procs = [
            subprocess.Popen([sys.executable, "-m", "plant_emulator", "--bus", self.spec, "--rig", "testbench",
                              "--pacing", "lockstep"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env),
            subprocess.Popen([sys.executable, "-m", "firmware_py", "--bus", self.spec, "--rig", "testbench",
                              "--pacing", "lockstep", "--controller", "adaptive", "--config", str(config)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)]

    def stop(self) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()


async def _until(pilot, condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await pilot.pause(0.05)


@pytest.mark.process
@pytest.mark.slow
def test_live_monitor_decodes_every_frame_its_estop_disables_the_valves_and_the_log_replays(tmp_path):
    """Emulator + controller + monitor on one bus: the monitor sees the controller READY, a
    fault injected into the plant (FORCE_LIMIT), and its own E-stop reaching the controller
    (ESTOP, valves DISABLED); nothing lost or rejected. A recorder on the same bus writes the
    log the replay test then reads."""
    peer = _Peer(tmp_path)
    bus, rec_bus = open_bus(peer.spec, recorder=True), open_bus(peer.spec, recorder=True)
    log_path = tmp_path / "live.blf"
    recorder = can.Notifier(rec_bus, [can.Logger(str(log_path))])
    view = BusView()
    sender = CommandSender(view, bus)
    app = MonitorApp(view, LiveSource(view, bus), "test", sender=sender)
    emu = Outbox("EMU_CTRL")
    seen = {}

    async def drive():
        async with app.run_test(size=(160, 48)) as pilot:
            await _until(pilot, lambda: view.snapshot().state == "READY", 90, "READY")
            start = view.snapshot()
            await pilot.pause(2.0)                          # the full traffic for a while
            seen["steady"] = (start, view.snapshot())
            v, i = emu.values, emu.index
            v[i["COMMAND"]], v[i["TARGET"]], v[i["FAULT"]] = EmuCommand.INJECT_FAULT, 1, EmuFault.OUT_OF_RANGE
            assert emu.encode()
            bus.send(emu.message)
            await _until(pilot, lambda: view.snapshot().state == "FAULT", 30, "the injected fault")
            seen["fault"] = view.snapshot()
            await pilot.press("e")                          # E-STOP: no confirmation
            await _until(pilot, lambda: view.snapshot().state == "ESTOP", 10, "ESTOP")
            await pilot.pause(0.5)
            app.redraw()
            await pilot.pause()
            seen["screen"] = text_of(app.query_one("#controller")) + text_of(app.query_one("#emcy"))
    try:
        asyncio.run(drive())
    finally:
        recorder.stop()
        for b in (bus, rec_bus):
            b.shutdown()
        peer.stop()

    start, end = seen["steady"]
    syncs = view.ok_by_message()["SYNC"]
    assert end.frames - start.frames > 1000 and syncs > 1000
    assert end.rejected == 0 and end.lost == 0, view.rejected_by_message()
    assert seen["fault"].fault == "FORCE_LIMIT"
    assert sender.sent == [(Command.ESTOP, sender.sent[0][1])]
    assert "ESTOP" in seen["screen"] and "FORCE_LIMIT" in seen["screen"]
    # on the bus (the recorder's log, stock cantools): the E-stop answered ACCEPTED, the first
    # CTRL_STATUS after that ack says ESTOP (one sent in the cycle the frame came in, before
    # the update that carries it out, may still say FAULT), and the valve reports DISABLED
    after = _after_the_estop(log_path)
    assert after["ack"] == "ACCEPTED" and after["status_after_ack"] == "ESTOP", after
    assert after["statuses_before_estop"] <= 1, after
    assert after["valve_disabled_cycles"] is not None and after["valve_disabled_cycles"] <= 3, after
    assert_replay_shows_the_log(log_path)


def _after_the_estop(path) -> dict:
    """What the bus carried after the first HOST_CMD ESTOP: its ack, the first CTRL_STATUS after
    the ack, how many CTRL_STATUS before the first saying ESTOP, and how many SYNCs later
    LEG_STATE_1 reported the valve DISABLED."""
    db = cantools.database.load_file(str(dbc_path()))
    ids = {CODECS[n].frame_id: n for n in ("HOST_CMD", "CTRL_ACK", "CTRL_STATUS", "SYNC", "LEG_STATE_1")}
    out = {"ack": None, "status_after_ack": None, "statuses_before_estop": 0, "valve_disabled_cycles": None}
    sent, estop_seen, syncs = False, False, 0
    with can.LogReader(str(path)) as reader:
        for msg in reader:
            name = ids.get(msg.arbitration_id)
            if name is None:
                continue
            v = db.decode_message(msg.arbitration_id, msg.data, decode_choices=True)
            if name == "HOST_CMD" and str(v["COMMAND"]) == "ESTOP":
                sent = True
            elif not sent:
                continue
            elif name == "CTRL_ACK" and out["ack"] is None:
                out["ack"] = str(v["RESULT"])
            elif name == "CTRL_STATUS":
                if out["ack"] is not None and out["status_after_ack"] is None:
                    out["status_after_ack"] = str(v["STATE"])
                if str(v["STATE"]) == "ESTOP":
                    estop_seen = True
                elif not estop_seen:
                    out["statuses_before_estop"] += 1
            elif name == "SYNC":
                syncs += 1
            elif name == "LEG_STATE_1" and str(v["VALVE_STATE"]) == "DISABLED" and out["valve_disabled_cycles"] is None:
                out["valve_disabled_cycles"] = syncs
    return out

def test_replay_scrolls_back_and_exports_the_window(tmp_path):
    """A recorded stretch replayed: freeze, one second back, export: the CSV is the log's
    LEG_STATE_1 positions of that second (cantools decode as the oracle)."""
    frames, path = Frames(), tmp_path / "synthetic.blf"
    with can.Logger(str(path)) as log:
        for k in range(2000):
            t = 1.7e9 + k * PERIOD_S
            for name, data in (("SYNC", frames("SYNC", COUNTER=k % 240 + 1)),
                               ("LEG_STATE_1", frames("LEG_STATE_1", POSITION=0.05 + 1e-5 * k, FORCE=1.0))):
                log(can.Message(timestamp=t, arbitration_id=CODECS[name].frame_id, data=data, is_extended_id=False))
    exported = {}

    async def scroll(app, pilot):
        await pilot.press("space", "left")
        app.export_dir = tmp_path
        await pilot.press("x")
        exported["end"] = app.frozen_at

    app = replay(path, until=scroll)
    with can.LogReader(str(path)) as reader:
        t0 = next(iter(reader)).timestamp             # BLF keeps its own time base
    assert exported["end"] == pytest.approx(t0 + 1999 * PERIOD_S - 1.0, abs=1e-5)
    files = list(tmp_path.glob("monitor-*.csv"))
    with open(files[0]) as f:
        rows = list(csv.DictReader(f))
    # the window's 5 s reach back before the log's start: every SYNC up to the frozen end
    assert len(files) == 1 and len(rows) == 1500 and app.messages[-1].startswith("exported 1500 rows")
    times = np.array([float(r["time_s"]) for r in rows])
    assert times[-1] <= exported["end"] + 1e-9
    k = np.round((times - t0) / PERIOD_S).astype(int)
    positions = np.array([float(r["leg1_position_mm"]) for r in rows])
    assert np.allclose(positions[1:], (0.05 + 1e-5 * (k[1:] - 1)) * 1e3, atol=0.005)


@pytest.mark.parametrize("argv, culprit", [
    (["monitor", "--replay", "{tmp}/garbage.blf"], "garbage.blf"),
    (["monitor", "--replay", "{tmp}/foreign.asc"], "no frame of this protocol"),
    (["monitor", "--replay", "{tmp}/run.txt"], "run.txt"),
    (["monitor", "--replay", "{tmp}/foreign.asc", "--control"], "--control"),
    (["monitor", "--bus", "can:nope"], "can:nope"),
    (["monitor", "--snapshot", "{tmp}/s.svg"], "--snapshot"),
    (["monitor", "--headless"], "--headless"),
])
def test_bad_monitor_input_is_one_line_and_exit_2(argv, culprit, tmp_path, capsys):
    (tmp_path / "garbage.blf").write_bytes(b"\x00not a log at all" * 10)
    (tmp_path / "run.txt").write_text("x")
    with can.Logger(str(tmp_path / "foreign.asc")) as log:        # a log of another protocol
        for k in range(50):
            log(can.Message(timestamp=k * 0.01, arbitration_id=0x7E5, data=b"\x01", is_extended_id=False))
    code = main([a.replace("{tmp}", str(tmp_path)) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and culprit in err and "Traceback" not in err, err


def test_snapshot_of_a_replay_writes_the_screen(tmp_path, capsys):
    frames, path = Frames(), tmp_path / "short.blf"
    with can.Logger(str(path)) as log:
        for k in range(100):
            for name, data in (("SYNC", frames("SYNC", COUNTER=k % 240 + 1)),
                               ("CTRL_STATUS", frames("CTRL_STATUS", STATE=int(State.READY)))):
                log(can.Message(timestamp=k * PERIOD_S, arbitration_id=CODECS[name].frame_id, data=data,
                                is_extended_id=False))
    assert main(["monitor", "--replay", str(path), "--speed", "0", "--snapshot", str(tmp_path / "s.svg"),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 200 and summary["state"] == "READY" and summary["e2e_rejected"] == 0
    svg = (tmp_path / "s.svg").read_text()
    assert svg.startswith("<svg") and "READY" in svg
