"""The controller on stock CANopen devices (`--devices canopen`): identified, configured by SDO
and read back before any NMT start, then its cycle through their PDOs, tracking as it does on
the project's own nodes; a rebooted device configured again before it is started; a
configuration that leaves a leg without a sample refused with one line."""

import math
from types import SimpleNamespace

import can
import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime.configure import ConfigurationError
from firmware_py.runtime.daemon import bus_budget_note
from firmware_py.runtime.hardware_canopen import CanopenHardware
from firmware_py.runtime.loop import ControllerLoop
from plant_emulator.loopback_bus import LoopbackBus
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.rigs import make_rig
from program.errors import UserInputError
from protocol import canopen_profile as cp
from protocol.bus import BusSpec
from protocol.canopen_layout import LAYOUT_FILE, load_layout
from protocol.devices import SDO_REQUEST_BASE, object_dictionary, written_values
from protocol.enums import Ack, Command, EmuFault, Fault, NmtCommand, NmtState, State, ValveState, WaypointFlag
from protocol.nodes import CONTROLLER_NODE
from tests.support.loops import (
    bus_loop,
    command,
    cycles,
    cycles_until_fault,
    cycles_while_starting,
    inject,
    nmt,
    send_waypoint,
    valve_states,
)

NMT_ID, SYNC_ID = 0x000, 0x080


class _Recording:
    """Wraps the in-process bus: the ids the controller sent, in order."""

    def __init__(self, bus):
        self.bus, self.order = bus, []
        self._send = bus.send
        bus.send = self.send

    def send(self, msg, timeout=None):
        self.order.append(msg.arbitration_id)
        self._send(msg, timeout)


def test_every_device_is_configured_and_read_back_before_any_is_started():
    loop, ctl, bus = bus_loop("hexapod", "model-based", activate=False, devices="canopen")
    sent = _Recording(bus)
    loop.activate()
    assert ctl.status.state is State.READY
    order = sent.order
    sdo = [i for i, frame in enumerate(order) if SDO_REQUEST_BASE < frame < SDO_REQUEST_BASE + 0x80]
    first_rpdo = next(i for i, frame in enumerate(order) if 0x201 <= frame <= 0x206)
    assert {order[i] - SDO_REQUEST_BASE for i in sdo} == {d.node for d in load_layout(6)}
    assert max(sdo) < order.index(NMT_ID) < order.index(SYNC_ID) <= first_rpdo
    # what each device holds is the layout's: its settings and its PDOs' SYNC starts
    for device in load_layout(6):
        held = written_values(bus.emulator.canopen.sdo.nodes[device.node])
        for index, sub, value in device.settings:
            assert held[(index, sub)] == value, (device.name, hex(index), sub)
        if device.sync_start:
            assert held[(0x1801, 6)] == device.sync_start
    assert all(state == NmtState.OPERATIONAL for state in bus.emulator.nmt.values())


def test_the_measurements_are_the_rigs_within_a_step():
    loop, ctl, bus = bus_loop("hexapod", "model-based", devices="canopen")
    cycles(loop, 40)
    sim, meas = bus.sim, loop.meas
    assert meas.fresh.all() and loop.stats.missing_frames == 0 and loop.stats.e2e_errors == 0
    np.testing.assert_allclose(meas.position_m, sim.position_m, atol=cp.POSITION_STEP_M)
    np.testing.assert_allclose(meas.force_n, sim.force_n, atol=cp.FORCE_STEP_N)
    assert meas.valve_state.tolist() == valve_states(bus) == [ValveState.ACTIVE] * 6
    assert np.all(meas.pa_pa > 1e5) and np.all(meas.ps_pa > 20e5)
    assert np.max(np.abs(meas.attitude_rad)) < 0.01


def _step(devices: str) -> np.ndarray:
    """The test bench's encoder stroke over a 20 mm move of 0.5 s, then 0.5 s of holding."""
    loop, ctl, bus = bus_loop("testbench", "pi", devices=devices)
    z = float(ctl.status.hold_m[0])
    flags = int(WaypointFlag.START | WaypointFlag.LAST)
    assert send_waypoint(ctl, 1, 0.0, 0.0, z + 0.02, segment=0.5, accel=0.1, flags=flags) is Ack.ACCEPTED
    strokes = []
    for _ in range(500):
        loop.cycle()
        strokes.append(bus.sim.position_m[0])
    assert ctl.status.fault is Fault.NONE
    return np.array(strokes)


def test_a_move_on_stock_devices_is_the_move_on_the_projects_own_nodes():
    own, stock = _step("hydrapod"), _step("canopen")
    assert stock[-1] - stock[0] == pytest.approx(0.02, abs=1e-3)
    assert np.max(np.abs(stock - own)) < 0.2e-3        # the same steps on the wire: the same motion


def test_a_device_that_reboots_is_configured_again_before_it_is_started():
    loop, ctl, bus = bus_loop("testbench", "pi", devices="canopen")
    cycles(loop, 20)
    nmt(bus, NmtCommand.RESET_NODE, 33)                 # the encoder reboots: its EDS's defaults, silent
    cycles(loop, ctl.cfg.supervisor.missing_frames_fault + 2)
    assert ctl.status.fault is Fault.SENSOR_TIMEOUT
    assert (0x1017, 0) not in written_values(bus.emulator.canopen.sdo.nodes[33])     # forgotten
    cycles(loop, math.ceil(0.1 / bus.period_s) + 1)      # its first heartbeat after the boot-up
    assert loop.hardware.nmt_state[33] == NmtState.PRE_OPERATIONAL
    ctl.host.command(int(Command.RESET), 0, 1)
    assert cycles_while_starting(loop)                   # identified and configured beside the cycle ...
    held = written_values(bus.emulator.canopen.sdo.nodes[33])
    assert held[(0x1017, 0)] == 100                      # ... the layout's settings written again
    assert bus.emulator.nmt[33] == NmtState.OPERATIONAL and ctl.status.state is State.IDLE
    cycles(loop, 10)
    assert command(ctl, Command.ENABLE) is Ack.ACCEPTED
    cycles(loop, 10)
    assert ctl.status.state is State.READY and valve_states(bus) == [ValveState.ACTIVE]


class _Store:
    """An SDO client that keeps what is written (canopen's `download`/`upload` surface)."""

    def __init__(self):
        self.held = {}

    def download(self, index, sub, data):
        self.held[(index, sub)] = bytes(data)

    def upload(self, index, sub):
        return self.held[(index, sub)]


def test_a_configuration_that_leaves_a_leg_without_its_position_is_refused(tmp_path):
    layout = tmp_path / "layout.toml"
    text = LAYOUT_FILE.read_text().replace('eds = "canopen-encoder.eds"', 'eds = "canopen-leg-sensors.eds"')
    layout.write_text(text)                              # the "encoder" is a measuring device: no position
    hardware = CanopenHardware(1, False, SimpleNamespace(), lambda: 0.0, layout=layout)
    with pytest.raises(ConfigurationError) as error:
        hardware.prepare(lambda node: _Store(), hardware.nodes)
    assert str(error.value) == "leg 1: no TPDO sent at every SYNC carries its position: not started"


def test_stock_devices_beyond_one_real_buss_budget_are_refused_with_the_rate_that_fits():
    with pytest.raises(UserInputError) as error:
        bus_budget_note("canopen", 6, 500.0, BusSpec("socketcan", "can0"))
    assert "one bus carries them at 342 Hz at most" in str(error.value)
    assert str(error.value).endswith("use --rate-hz 342")
    assert "run as asked" in bus_budget_note("canopen", 6, 500.0, BusSpec("socketcan", "vcan0"))
    assert bus_budget_note("canopen", 6, 342.0, BusSpec("socketcan", "can0")) == ""
    assert bus_budget_note("canopen", 1, 500.0, BusSpec("socketcan", "can0")) == ""
    assert bus_budget_note("hydrapod", 6, 500.0, BusSpec("socketcan", "can0")) == ""


def test_the_valve_rpdo_carries_the_control_word_and_setpoint_of_the_commands():
    loop, ctl, bus = bus_loop("testbench", "pi", devices="canopen")
    cycles(loop, 5)
    data = bus.last_sent[0x201]
    od = object_dictionary("canopen-valve.eds", 1)
    assert od[0x1600][1].default >> 16 == cp.CONTROL_WORD[0]
    word, setpoint = data[0] | data[1] << 8, int.from_bytes(data[2:4], "little", signed=True)
    cmd = loop.cmd
    assert cp.control_bits(word) == tuple(bool(x) for x in (cmd.enable[0], cmd.hold[0], cmd.active[0], cmd.reset[0]))
    assert setpoint == round(cmd.spool[0] * cp.SPOOL_FULL_SCALE)


@pytest.mark.parametrize("target,fault,expect,within", [
    (CONTROLLER_NODE, EmuFault.DROP, Fault.VALVE_FAULT, 6),      # no RPDO: the valve's timeout, its EMCY
    (1, EmuFault.DROP, Fault.SENSOR_TIMEOUT, 6),                 # leg 1's TPDOs lost
    (33, EmuFault.SILENT, Fault.HEARTBEAT_LOST, None),           # the encoder's heartbeat stops
])
def test_on_stock_devices_a_lost_frame_or_node_faults_as_on_the_projects_own(target, fault, expect, within):
    loop, ctl, bus = bus_loop("testbench", "pi", devices="canopen")
    cycles(loop, 20)
    emergencies = loop.stats.emergencies
    inject(bus, target, fault)
    limit = within or math.ceil(ctl.cfg.timing.heartbeat_timeout_s / bus.period_s) + 60
    taken = cycles_until_fault(loop, limit)
    assert ctl.status.fault is expect and taken <= limit
    if fault is EmuFault.DROP and target == CONTROLLER_NODE:
        assert valve_states(bus) == [ValveState.FAULT_HOLD] and loop.stats.emergencies > emergencies


@pytest.mark.parametrize("node,expect", [(33, Fault.SENSOR_FAULT), (49, Fault.SENSOR_FAULT), (1, Fault.VALVE_FAULT)])
def test_an_emcy_names_its_device_a_sensor_or_the_valve(node, expect):
    loop, ctl, bus = bus_loop("testbench", "pi", devices="canopen")
    cycles(loop, 20)
    bus.deliver(can.Message(arbitration_id=0x80 + node, data=bytes([0x00, 0x50, 0x01, 0, 0, 0, 0, 0]),
                            is_extended_id=False))         # CiA 301 0x5000: device hardware
    cycles(loop, 2)
    assert ctl.status.fault is expect


def test_which_object_travels_where_is_the_devices_mapping_not_code(tmp_path):
    """A measuring device whose pressure TPDO carries the supply first, then chamber A and B
    (its DCF, not the shipped EDS): emulator and controller both follow it, and every
    pressure lands where it belongs."""
    eds = (LAYOUT_FILE.parent / "canopen-leg-sensors.eds").read_text()
    for sub, entry in ((1, "0x71300410"), (2, "0x71300210"), (3, "0x71300310")):
        section = f"[1A01sub{sub}]"
        head, rest = eds.split(section, 1)
        old = rest.split("DefaultValue=", 1)[1].split("\n", 1)[0]
        eds = head + section + rest.replace(f"DefaultValue={old}", f"DefaultValue={entry}", 1)
    dcf = tmp_path / "leg-sensors.dcf"
    dcf.write_text(eds)
    layout = tmp_path / "layout.toml"
    layout.write_text(LAYOUT_FILE.read_text().replace('eds = "canopen-leg-sensors.eds"', f'eds = "{dcf}"'))
    cfg = load_emulator_config()
    ctl = Controller(load_config(), "testbench", 0.002, CONTROLLER_NAMES["pi"])
    bus = LoopbackBus(make_rig("testbench", cfg), cfg, devices="canopen", layout=layout)
    loop = ControllerLoop(bus, ctl, 500.0, "lockstep", clock=bus.clock, log=lambda _: None, devices="canopen",
                          layout=layout)
    loop.activate()
    cycles(loop, 40)
    assert ctl.status.fault is Fault.NONE and loop.meas.pressure_valid[0]
    truth = bus.sim.pressure[0]                      # PA, PB, PS as the emulator sampled them last
    measured = (loop.meas.pa_pa[0], loop.meas.pb_pa[0], loop.meas.ps_pa[0])
    # a sample a few SYNCs older than the truth's: within 0.15 bar, where A and B differ by ~0.4
    np.testing.assert_allclose(measured, truth, atol=0.15e5)
    assert abs(truth[0] - truth[1]) > 0.3e5
    assert loop.meas.ps_pa[0] > 2 * loop.meas.pa_pa[0]            # the supply, not a chamber
