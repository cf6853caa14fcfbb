"""The payload identified by the controller (rig_model.HexapodModel.update_payload): an
undeclared payload on the emulated platform found from the load cells while holding, and
taken into the inverse dynamics the computed torque and the waypoint check run."""

import numpy as np
import pytest

from firmware_py.config import load_config
from hil.in_process import InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import State


@pytest.mark.parametrize("payload_kg", [6.0])
def test_an_undeclared_payload_is_found_within_two_seconds_of_holding(payload_kg):
    loop = InProcessLoop(load_config(), load_emulator_config(), "computed-torque", load_kg=payload_kg)
    loop.activate(1000)                                   # 2 s holding at home
    status, rig = loop.status, loop.ctl.rig
    assert status.state is State.READY
    assert status.payload_mass_kg == pytest.approx(payload_kg, rel=0.05)
    platform_com = np.asarray(rig.geometry.platform.com_m)   # the emulator's payload sits there
    assert status.payload_com_m[:2] == pytest.approx(platform_com[:2], abs=0.005)
    for dynamics in (rig.platform.dynamics, rig.computed_torque.dynamics, rig.check.loads.dynamics):
        assert dynamics.masses[0] == pytest.approx(rig.geometry.platform.mass_kg + payload_kg, rel=0.05)


def test_without_estimation_the_declared_payload_stands():
    cfg = load_config(overrides={"payload": {"estimate": False}, "hexapod": {"payload_kg": 2.0}})
    loop = InProcessLoop(cfg, load_emulator_config(), "computed-torque", load_kg=4.0)
    loop.activate(500)
    rig = loop.ctl.rig
    assert rig.payload is None and np.isnan(loop.status.payload_mass_kg)
    assert rig.computed_torque.dynamics.masses[0] == pytest.approx(rig.geometry.platform.mass_kg)


def test_the_payload_and_the_clock_go_on_the_bus_every_48th_sync():
    """CTRL_PAYLOAD, decoded by cantools from the DBC: the estimate of an undeclared 3 kg;
    CTRL_CLOCK beside it: holding, at full rate."""
    from hil.in_process import bus_loop
    from protocol.codec import CODECS
    from protocol.dbc import load_database
    emulator = load_emulator_config(overrides={"hexapod": {"payload_kg": 3.0}})
    loop, ctl, bus = bus_loop(load_config(), emulator, "hexapod", "computed-torque")
    frame_id = CODECS["CTRL_PAYLOAD"].frame_id
    for _ in range(800):
        loop.cycle()
    clock_id = CODECS["CTRL_CLOCK"].frame_id
    before, clocks_before = bus.sent[frame_id], bus.sent[clock_id]
    for _ in range(960):
        loop.cycle()
    assert bus.sent[frame_id] - before == bus.sent[clock_id] - clocks_before == 960 // 48
    clock = load_database().decode_message(clock_id, bus.last_sent[clock_id])
    assert clock["MOVING"] == 0 and clock["RATE"] == 1.0 and clock["MOTION_TIME"] == 0.0
    decoded = load_database().decode_message(frame_id, bus.last_sent[frame_id])
    assert decoded["ESTIMATING"] == 1 and decoded["COM_PLACED"] == 1
    assert decoded["MASS"] == pytest.approx(3.0, abs=0.15)
    assert abs(decoded["COM_X"]) < 5.0 and abs(decoded["COM_Y"]) < 5.0     # mm, at the platform's centre
