"""The controller's real loop against the in-process fake bus (tests/fake_bus.py): what the
supervisor, allocation and identification tests drive."""

from __future__ import annotations

from firmware_py.config import load_config
from firmware_py.controller import Controller
from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from firmware_py.runtime.loop import ControllerLoop
from hil.design.simulate import send_waypoint  # noqa: F401  (the tests' one way to send a waypoint)
from protocol.enums import State
from protocol.nodes import rig_nodes
from tests.fake_bus import EmulatedHexapodBus, FakeBus


def make_loop(rig: str, controller: str, overrides: dict | None = None, emulated: bool = False):
    """(loop, controller, bus), activated: the controller READY at home; `emulated`: the
    emulator's hexapod behind the bus instead of independent identified legs."""
    # the identified legs' load cells are noiseless: the frozen load-cell check would see them
    noiseless = {"residuals": {"load_cell_noise_n": 0.0}}
    cfg = load_config(overrides=overrides if emulated else {**noiseless, **(overrides or {})})
    ctl = Controller(cfg, rig, 0.002, CONTROLLER_NAMES[controller])
    if emulated:
        from plant_emulator.params import load_config as load_emulator_config
        from plant_emulator.rigs import HexapodRig
        bus = EmulatedHexapodBus(HexapodRig(load_emulator_config()), ctl.home_strokes, nodes=rig_nodes(6))
    else:
        bus = FakeBus(ctl.n, ctl.home_strokes.copy(), nodes=rig_nodes(ctl.n))
    loop = ControllerLoop(bus, ctl, 500.0, "lockstep", log=lambda _: None)
    loop.activate()
    return loop, ctl, bus


def cycles(loop, n: int) -> None:
    for _ in range(n):
        loop.cycle()


def cycles_until_fault(loop, limit: int) -> int:
    """Cycles run until the controller faulted (the last one included), at most `limit`."""
    for k in range(1, limit + 1):
        loop.cycle()
        if loop.controller.state is State.FAULT:
            return k
    return limit


def valve_words(loop):
    """What the controller last wrote to leg 1: (D, H, M, spool)."""
    box = loop.out_cmd[0]
    v = box.values
    return v[box.index["CW_D"]], v[box.index["CW_H"]], v[box.index["CW_M"]], v[box.index["SPOOL_SETPOINT"]]
