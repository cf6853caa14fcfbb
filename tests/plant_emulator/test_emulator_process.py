"""The emulator as a separate process on udp_multicast, driven by a scripted python-can peer
(this test plays the controller): NMT, SYNC-driven frames, the CiA 408 state machine, the
command timeout with EMCY, reset, EMU_CTRL, and a clean exit on SIGTERM with counters."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from protocol.bus import open_bus
from protocol.codec import CODECS, FrameDecoder
from protocol.e2e import RxStatus
from tests.support.buses import GROUP, free_port

ROOT = Path(__file__).resolve().parents[2]
FULL_SCALE_V = 10.0


class Peer:
    """A minimal controller: SYNC producer, VALVE_CMD_1 sender, frame recorder."""

    def __init__(self, spec):
        self.bus = open_bus(spec)
        self.decoder = FrameDecoder(["LEG_STATE_1", "VALVE_STATUS_1", "LEG_PRESSURE_1", "EMCY_1", "HEARTBEAT_1"])
        self.counter = 0
        self.cmd = CODECS["VALVE_CMD_1"]
        self.cmd_values = self.cmd.new_values()
        self.cmd_msg = can.Message(arbitration_id=self.cmd.frame_id, data=self.cmd.new_buffer(), is_extended_id=False)
        self.emu = CODECS["EMU_CTRL"]
        self.emu_values = self.emu.new_values()
        self.emu_msg = can.Message(arbitration_id=self.emu.frame_id, data=self.emu.new_buffer(), is_extended_id=False)
        self.emergencies = []
        self.latency_s = []

    def send_raw(self, frame_id, data):
        self.bus.send(can.Message(arbitration_id=frame_id, data=bytes(data), is_extended_id=False))

    def wait_for(self, name, timeout=10.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.bus.recv(0.05)
            if msg is not None and self._record(msg) == name:
                return True
        return False

    def _record(self, msg):
        status = self.decoder.receive_message(msg)
        name = next((n for n in self.decoder.names if CODECS[n].frame_id == msg.arbitration_id), None)
        if name == "EMCY_1" and status is RxStatus.OK:
            self.emergencies.append(self.decoder.values["EMCY_1"].copy())
        return name if status is RxStatus.OK else None

    def cycle(self, command=None):
        """One SYNC: send it, collect this cycle's LEG_STATE_1, then send the command (if any)."""
        self.counter = self.counter % 240 + 1
        start = time.monotonic()
        self.send_raw(CODECS["SYNC"].frame_id, [self.counter])
        got = False
        while time.monotonic() - start < 2.0:
            msg = self.bus.recv(0.05)
            if msg is not None and self._record(msg) == "LEG_STATE_1":
                self.latency_s.append(time.monotonic() - start)
                got = True
                break
        assert got, f"no LEG_STATE_1 after SYNC {self.counter}"
        if command is not None:
            d, h, m, r, volts = command
            i = self.cmd.index
            self.cmd_values[i["CW_D"]], self.cmd_values[i["CW_H"]] = d, h
            self.cmd_values[i["CW_M"]], self.cmd_values[i["CW_R"]] = m, r
            self.cmd_values[i["SPOOL_SETPOINT"]] = volts / FULL_SCALE_V
            self.cmd.encode_into(self.cmd_values, self.cmd_msg.data)
            self.bus.send(self.cmd_msg)
        return self.leg_state()

    def leg_state(self):
        values = self.decoder.values["LEG_STATE_1"]
        idx = CODECS["LEG_STATE_1"].index
        return int(values[idx["VALVE_STATE"]]), values[idx["POSITION"]], values[idx["FORCE"]]

    def emu_ctrl(self, command, target=0, fault=0, load_kg=0.0, param=0):
        self.emu_values[2:] = (command, target, fault, load_kg, param)
        self.emu.encode_into(self.emu_values, self.emu_msg.data)
        self.bus.send(self.emu_msg)


WATCHDOG_PERIODS = 1000.0      # the valves' SYNC watchdog here: 2 s of wall clock


@pytest.fixture
def emulator_process(tmp_path):
    spec = f"udp_multicast:{GROUP}:{free_port()}"
    summary = tmp_path / "summary.json"
    # this test drives the command timeout (3 SYNCs without VALVE_CMD); the wall-clock SYNC
    # watchdog would trip whenever this process is not scheduled for 6 ms (a loaded machine)
    config = tmp_path / "emulator.toml"
    config.write_text(f"[nodes]\nsync_timeout_periods = {WATCHDOG_PERIODS}\n")
    peer = Peer(spec)
    proc = subprocess.Popen([sys.executable, "-m", "plant_emulator", "--bus", spec, "--rig", "testbench",
                             "--load-kg", "3", "--summary", str(summary), "--config", str(config),
                             "--pacing", "lockstep"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        yield peer, proc, summary
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)
        peer.bus.shutdown()


@pytest.mark.process
def test_scripted_peer_drives_the_emulator(emulator_process):
    peer, proc, summary = emulator_process
    assert peer.wait_for("HEARTBEAT_1", timeout=60.0), "no heartbeat from the emulator"
    peer.send_raw(CODECS["NMT"].frame_id, [1, 0])                 # NMT start all
    time.sleep(0.05)
    state, position, force = peer.cycle()
    assert state == 1                                              # DISABLED after boot
    assert 0.100 < position < 0.200                                # starts near 150 mm, 0.125 mm grid
    assert abs(position / 0.000125 - round(position / 0.000125)) < 1e-6
    assert 30.0 < force < 80.0                                     # (1.35 + 3) kg on the rod, noisy
    peer.cycle((1, 1, 0, 0, 0.0))                                  # ask HOLD
    state, *_ = peer.cycle((1, 1, 1, 0, 0.0))                      # applied at the next SYNC
    assert state == 2
    state, *_ = peer.cycle((1, 1, 1, 0, 1.0))
    assert state == 3                                              # ACTIVE
    start = peer.leg_state()[1]
    for _ in range(100):                                           # 0.2 s at +1 V: it rises
        state, position, _ = peer.cycle((1, 1, 1, 0, 1.0))
    assert state == 3 and position - start > 0.002
    # stop commanding: the last command is applied at the next SYNC; then FAULT_HOLD at the
    # 3rd SYNC that found no new VALVE_CMD, with EMCY
    states = [peer.cycle()[0] for _ in range(4)]
    assert states == [3, 3, 3, 4], states
    assert peer.wait_for("EMCY_1", timeout=1.0) or peer.emergencies
    code, _, emcy_state, detail, _, info = peer.emergencies[0]
    assert (code, emcy_state, detail, info) == (0x8250, 4, 1, 3)
    held = peer.leg_state()[1]
    positions = [peer.cycle((1, 1, 1, 0, 1.0))[1] for _ in range(50)]   # commands do not un-fault
    assert peer.leg_state()[0] == 4
    assert abs(positions[-1] - held) < 0.002                       # it stops within 2 mm ...
    assert abs(positions[-1] - positions[25]) < 0.00025            # ... and stays
    peer.cycle((1, 1, 0, 1, 0.0))                                  # rising edge of R
    state, *_ = peer.cycle((1, 1, 0, 0, 0.0))
    assert state == 2
    # EMU_CTRL: corrupt LEG_STATE_1 for 5 cycles -> CRC errors counted by the receiver
    before = int(peer.decoder.counts[0, RxStatus.CRC_ERROR])
    peer.emu_ctrl(2, target=1, fault=4, param=5)
    for _ in range(3):
        peer.counter = peer.counter % 240 + 1
        peer.send_raw(CODECS["SYNC"].frame_id, [peer.counter])
        deadline = time.monotonic() + 0.5
        while time.monotonic() < deadline:
            msg = peer.bus.recv(0.05)
            if msg is not None:
                peer._record(msg)
                if msg.arbitration_id == CODECS["LEG_STATE_1"].frame_id:
                    break
    assert int(peer.decoder.counts[0, RxStatus.CRC_ERROR]) - before >= 2
    latency = np.array(peer.latency_s)
    assert np.percentile(latency, 50) < 0.05                       # answers promptly after SYNC
    # SYNC stops: the held valve faults on its watchdog (WATCHDOG_PERIODS, 2 s) with an EMCY
    assert peer.wait_for("EMCY_1", timeout=WATCHDOG_PERIODS * 0.002 + 3.0)
    code, _, emcy_state, detail, *_ = peer.emergencies[-1]
    assert (code, emcy_state, detail) == (0x8100, 4, 2)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "emulator: rig=testbench" in out and "e2e_errors=0" in out, out
    report = json.loads(summary.read_text())
    assert report["syncs"] >= 150 and report["valve_faults"] == 2
    assert report["frames_out"] > report["syncs"]
