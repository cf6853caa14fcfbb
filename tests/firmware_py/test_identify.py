"""Identify before starting: the controller reads every node's device type and identity by
SDO and starts none (no NMT start, no valve command) when one is not its configured device;
the refusal is one line naming the node and the object."""

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
from canopen.sdo.exceptions import SdoAbortedError

from firmware_py.config import ConfigError, load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime.identify import IdentityError
from firmware_py.runtime.loop import ControllerLoop
from plant_emulator.loopback_bus import LoopbackBus
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.rigs import make_rig
from protocol.codec import CODECS
from protocol.devices import SDO_REQUEST_BASE
from protocol.enums import Ack, Command, NmtCommand, NmtState, State
from protocol.outbox import Outbox
from tests.support.buses import GROUP, free_port
from tests.support.loops import bus_loop, command, cycles, cycles_while_starting, frames_sent

STOCK_VALVE = str(Path(__file__).parents[1] / "data" / "stock-valve.eds")
NMT, VALVE_CMD_1 = CODECS["NMT"].frame_id, CODECS["VALVE_CMD_1"].frame_id


class _Recorded(LoopbackBus):
    """The loopback bus, remembering the order of what the controller sent."""

    def __init__(self, *args):
        super().__init__(*args)
        self.order: list[int] = []

    def send(self, msg, timeout=None) -> None:
        self.order.append(msg.arbitration_id)
        super().send(msg, timeout)


def _loop(rig: str = "hexapod", emulator_overrides=None, controller_overrides=None):
    emulator = load_emulator_config(overrides=emulator_overrides)
    bus = _Recorded(make_rig(rig, emulator), emulator)
    ctl = Controller(load_config(overrides=controller_overrides), rig, 0.002, CONTROLLER_NAMES["pi"])
    lines = []
    return ControllerLoop(bus, ctl, 500.0, "lockstep", clock=bus.clock, log=lines.append), bus, lines


def test_every_node_is_identified_before_any_is_started():
    loop, bus, lines = _loop()
    loop.activate()
    requests = [i for i, frame in enumerate(bus.order) if SDO_REQUEST_BASE < frame <= SDO_REQUEST_BASE + 7]
    assert {bus.order[i] - SDO_REQUEST_BASE for i in requests} == set(range(1, 8))
    assert max(requests) < bus.order.index(NMT) < bus.order.index(VALVE_CMD_1)
    assert any(line.startswith("identified node(s) [1, 2, 3, 4, 5, 6, 7] as configured") for line in lines)
    assert loop.controller.status.state.name == "READY"


@pytest.mark.parametrize("rig", ["hexapod", "testbench"])
def test_stock_valves_the_configuration_does_not_name_are_never_started(rig):
    loop, bus, _ = _loop(rig, emulator_overrides={"nodes": {"leg_eds": STOCK_VALVE}})
    with pytest.raises(IdentityError) as refused:
        loop.activate()
    assert str(refused.value) == ("node 1 (LEG1): vendor id (0x1018:1) is 0x0000ABCD, hydrapod-leg.eds says "
                                  "0x48594450: not started")
    assert NMT not in bus.order and VALVE_CMD_1 not in bus.order


def test_the_rig_s_eds_configured_starts_the_same_valves(tmp_path):
    loop, bus, _ = _loop("testbench", emulator_overrides={"nodes": {"leg_eds": STOCK_VALVE}},
                         controller_overrides={"devices": {"leg_eds": STOCK_VALVE}})
    loop.activate()
    assert NMT in bus.order


def test_one_node_of_another_product_is_named():
    loop, bus, _ = _loop()
    bus.emulator.devices.nodes[4].set_data(0x1018, 2, (0x0D63).to_bytes(4, "little"))
    with pytest.raises(IdentityError, match=r"^node 4 \(LEG4\): product code \(0x1018:2\) is 0x00000D63, "):
        loop.activate()
    assert NMT not in bus.order


def test_a_node_that_does_not_answer_sdo_is_named_after_the_timeout(caplog):
    caplog.set_level(logging.INFO, logger="canopen")
    loop, bus, _ = _loop(controller_overrides={"devices": {"sdo_timeout_ms": 50.0}})
    del bus.emulator.devices._request[SDO_REQUEST_BASE + 5]       # its heartbeat, no SDO server
    with pytest.raises(IdentityError, match=r"^node 5 \(LEG5\): no SDO answer reading its device type "
                                            r"\(0x1000:0\) within 50 ms$"):
        loop.activate()
    assert NMT not in bus.order
    # the line above is all it says: not canopen's own log of the abort it sent too
    assert not [r for r in caplog.records if r.name.startswith("canopen")], caplog.records


def test_an_aborted_read_is_named_with_the_abort():
    loop, bus, _ = _loop()

    def refuse(index, subindex, od):
        if (index, subindex) == (0x1018, 1):
            raise SdoAbortedError(0x06020000)
    bus.emulator.devices.nodes[7].add_read_callback(refuse)
    with pytest.raises(IdentityError, match=r"^node 7 \(IMU\): reading its vendor id \(0x1018:1\) was aborted: "
                                            r"Code 0x06020000, Object does not exist"):
        loop.activate()


def test_a_configured_eds_that_is_not_there_is_one_line():
    with pytest.raises(ConfigError, match=r"\[devices\]: missing.eds: no such EDS file"):
        load_config(overrides={"devices": {"leg_eds": "missing.eds"}})


@pytest.mark.process
def test_the_daemon_refuses_a_stock_valve_in_one_line_and_exits_2(tmp_path):
    spec = f"udp_multicast:{GROUP}:{free_port()}"
    config = tmp_path / "emulator.toml"
    config.write_text(f'[nodes]\nleg_eds = "{STOCK_VALVE}"\n')
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    emulator = subprocess.Popen([sys.executable, "-m", "plant_emulator", "--bus", spec, "--rig", "testbench",
                                 "--pacing", "lockstep", "--config", str(config)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        controller = subprocess.run([sys.executable, "-m", "firmware_py", "--bus", spec, "--rig", "testbench",
                                     "--pacing", "lockstep"], capture_output=True, text=True, env=env, timeout=60)
    finally:
        emulator.kill()
        emulator.communicate(timeout=10)
    refusal = [line for line in controller.stderr.splitlines() if "activation" in line]
    assert controller.returncode == 2, controller.stderr[-2000:]
    assert refusal == ["controller: activation refused: node 1 (LEG1): vendor id (0x1018:1) is 0x0000ABCD, "
                       "hydrapod-leg.eds says 0x48594450: not started"]
    assert "Traceback" not in controller.stderr


def test_a_node_that_reboots_as_another_device_is_not_started_again_on_reset():
    loop, ctl, bus = bus_loop("testbench", "pi")
    lines = []
    loop.log = lines.append
    cycles(loop, 20)
    box = Outbox("NMT")
    box.values[:] = (int(NmtCommand.RESET_NODE), 1)          # the node reboots ...
    assert box.encode()
    bus.emulator.handle(box.message)
    bus.emulator.devices.nodes[1].set_data(0x1018, 2, (0x0D63).to_bytes(4, "little"))   # ... as another product
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault + 2)
    assert ctl.status.state is State.FAULT
    starts = frames_sent(bus, "NMT")
    assert command(ctl, Command.RESET) is Ack.ACCEPTED
    assert cycles_while_starting(loop)
    cycles(loop, 10)
    assert frames_sent(bus, "NMT") == starts and bus.emulator.nmt[1] == NmtState.PRE_OPERATIONAL
    assert [line for line in lines if line.startswith("restart refused")] == [
        "restart refused: node 1 (LEG1): product code (0x1018:2) is 0x00000D63, hydrapod-leg.eds says "
        "0x00000408: not started"]


def test_a_controller_started_again_starts_nodes_already_operational():
    """A new master (a restarted controller) identifies the nodes, then sends NMT start even
    though they are OPERATIONAL: the nodes restart its frames' E2E counters there."""
    loop, bus, _ = _loop("testbench")
    loop.activate()
    again = ControllerLoop(bus, Controller(load_config(), "testbench", 0.002, CONTROLLER_NAMES["pi"]), 500.0,
                           "lockstep", clock=bus.clock, log=lambda _: None)
    bus.order.clear()
    again.activate()
    assert SDO_REQUEST_BASE + 1 in bus.order
    assert bus.order.index(SDO_REQUEST_BASE + 1) < bus.order.index(NMT) < bus.order.index(VALVE_CMD_1)
