"""The controller daemon as a separate process on udp_multicast against a scripted
python-can peer playing the test bench's leg node (its SDO answers canopen's LocalNode from
the shipped EDS): >= 2,000 cycles without an E2E error, then SIGTERM -> valves HOLD, then
DISABLED, exit 0 with the one-line summary."""

import json
import os
import random
import signal
import subprocess
import sys
import time

import can
import canopen
import pytest

from protocol.bus import open_bus
from protocol.codec import CODECS, FrameDecoder
from protocol.devices import SDO_REQUEST_BASE, local_node
from protocol.e2e import RxStatus
from tests.support.buses import GROUP, free_port

CYCLES = 2500


@pytest.mark.process
def test_daemon_runs_against_a_scripted_peer_and_shuts_down_safely(tmp_path):
    spec = f"udp_multicast:{GROUP}:{free_port()}"
    bus = open_bus(spec)
    summary = tmp_path / "summary.json"
    proc = subprocess.Popen([sys.executable, "-m", "firmware_py", "--bus", spec, "--rig", "testbench",
                             "--pacing", "lockstep", "--controller", "adaptive", "--summary", str(summary)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    codec = CODECS["LEG_STATE_1"]
    state = can.Message(arbitration_id=codec.frame_id, data=codec.new_buffer(), is_extended_id=False)
    values = codec.new_values()
    heartbeat = can.Message(arbitration_id=0x701, data=bytearray([127]), is_extended_id=False)
    decoder = FrameDecoder(["VALVE_CMD_1", "SYNC", "NMT", "CTRL_STATUS"])
    cmd = CODECS["VALVE_CMD_1"].index
    valve_state, latched = 1, None
    noise = random.Random(3)
    sdo = canopen.Network(bus)                  # answers the controller's identification
    sdo.add_node(local_node(1, "hydrapod-leg.eds"))
    syncs, commands, words = 0, 0, []
    next_heartbeat = 0.0
    deadline = time.monotonic() + 120.0
    terminated_at = None
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            now = time.monotonic()
            if now >= next_heartbeat:
                bus.send(heartbeat)
                next_heartbeat = now + 0.1
            msg = bus.recv(0.01)
            if msg is None:
                continue
            if msg.arbitration_id == SDO_REQUEST_BASE + 1:
                sdo.notify(msg.arbitration_id, msg.data, msg.timestamp)
                continue
            status = decoder.receive_message(msg)
            if msg.arbitration_id == 0x000 and status is RxStatus.OK and decoder.values["NMT"][0] == 1:
                heartbeat.data[0] = 5                                       # OPERATIONAL
                bus.send(heartbeat)
            elif msg.arbitration_id == CODECS["SYNC"].frame_id:
                syncs += 1
                if latched is not None:                                     # CiA 408, applied at SYNC
                    d, h, m = latched
                    valve_state = 1 if not (d and h) else (3 if m and valve_state in (2, 3) else 2)
                    latched = None
                values[codec.index["VALVE_STATE"]] = valve_state
                values[codec.index["POSITION"]] = 0.150
                values[codec.index["FORCE"]] = 13.2 + noise.gauss(0.0, 0.3)     # a load cell's noise
                codec.encode_into(values, state.data)
                bus.send(state)
                if syncs == CYCLES:
                    proc.send_signal(signal.SIGTERM)
                    terminated_at = syncs
            elif msg.arbitration_id == CODECS["VALVE_CMD_1"].frame_id:
                commands += 1
                v = decoder.values["VALVE_CMD_1"]
                latched = (v[cmd["CW_D"]] > 0.5, v[cmd["CW_H"]] > 0.5, v[cmd["CW_M"]] > 0.5)
                words.append(latched)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        bus.shutdown()
    assert proc.returncode == 0, err[-2000:]
    assert terminated_at == CYCLES and syncs >= CYCLES
    counts = decoder.counts[decoder.slot["VALVE_CMD_1"]]
    assert counts[RxStatus.OK] == commands >= CYCLES
    assert sum(counts) - counts[RxStatus.OK] - counts[RxStatus.NO_NEW_DATA] == 0      # no E2E error seen
    line = out.strip().splitlines()[-1]
    assert line.startswith("controller: rig=testbench controller=adaptive") and "e2e_errors=0" in line, out
    report = json.loads(summary.read_text())
    assert report["cycles"] >= CYCLES and report["e2e_errors"] == 0 and report["faults"] == 0
    assert report["state"] == "READY"
    # the valves were ACTIVE while running, then HOLD, then DISABLED to the end
    assert (True, True, True) in words
    tail = words[-8:]
    hold_then_disable = [w for w in words[words.index((True, True, True)):] if w != (True, True, True)]
    assert hold_then_disable[0] == (True, True, False)
    assert all(w == (False, False, False) for w in tail[-3:])
