"""Run in a fresh process (`python -m tests.support.first_motion_probe RIG`): activate a
controller on the in-process bus with the emulator behind it, then drive every controller
through every motion and command once; print
the numba kernels that gained a compiled or cache-loaded signature after activation (JSON).
Each gain is a compile (0.3-0.7 s) or a cache load (ms) inside a control cycle."""

from __future__ import annotations

import json
import sys

from program.numba_cache import configure

configure(prune=False)

from numba.core.registry import CPUDispatcher  # noqa: E402

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES  # noqa: E402
from protocol.enums import Command, State  # noqa: E402
from tests.support.loops import bus_loop, command, cycles, send_waypoint  # noqa: E402

PACKAGES = ("firmware_py", "protocol", "physics")


def signatures() -> dict[str, int]:
    out = {}
    for name, module in list(sys.modules.items()):
        if name.split(".")[0] in PACKAGES:
            for obj in list(vars(module).values()):
                if isinstance(obj, CPUDispatcher):
                    out[f"{obj.__module__}.{obj.__name__}"] = len(obj.signatures)
    return out


def exercise(loop, ctl) -> list[str]:
    """Every controller: HOME, PARK, STOP, ENABLE, a waypoint and START, ESTOP, RESET, ENABLE."""
    seen = []
    seq = 0
    status = ctl.status
    for name, kind in CONTROLLER_NAMES.items():
        assert command(ctl, Command.SELECT_CONTROLLER, kind).name == "ACCEPTED", name
        for host_command, n in ((Command.HOME, 200), (Command.PARK, 30), (Command.STOP, 400),
                                (Command.ENABLE, 20)):
            command(ctl, host_command)
            cycles(loop, n)
        x, y, z = ctl.rig.home_pose
        seq += 1
        send_waypoint(ctl, seq, x, y, z + 0.005, segment=0.5, accel=0.1, flags=3)
        command(ctl, Command.START)
        cycles(loop, 300)
        for host_command, n in ((Command.ESTOP, 5), (Command.RESET, 20), (Command.ENABLE, 20)):
            command(ctl, host_command)
            cycles(loop, n)
        fault = f" {status.fault.name} leg {status.fault_leg}" if status.state is State.FAULT else ""
        seen.append(f"{name}: {status.state.name}{fault}")
    return seen


def main(rig: str) -> None:
    loop, ctl, _ = bus_loop(rig, "pi")
    before = signatures()
    states = exercise(loop, ctl)
    after = signatures()
    gained = sorted(k for k, n in after.items() if n > before.get(k, 0))
    print(json.dumps({"kernels": len(after), "gained": gained, "states": states,
                      "ready": ctl.status.state is State.READY}))


if __name__ == "__main__":
    main(sys.argv[1])
