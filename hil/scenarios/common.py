"""Pieces the scenarios share: what was running when (from the log), and host moves."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
from hil.logdata import LogData
from hil.metrics import last_value_before
from plant_emulator.params import EmulatorConfig
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import EmuCommand, WaypointFlag

NAME_OF_CONTROLLER = {v: k for k, v in CONTROLLER_NAMES.items()}
# the thesis's per-leg controllers swing the hexapod's platform up to ~100 mm (docs/MEASUREMENTS.md
# "Hexapod gains"): the experiments that run them widen the platform's tracking bound to this
THESIS_PLATFORM_LIMITS = {"limits": {"platform_error_max_mm": 150.0, "platform_angle_max_deg": 20.0}}


VALVE_FULL_SCALE_V = 10.0          # VALVE_CMD's 100 % spool setpoint = 10 V of the thesis's u
NEW_CONTROLLER = "computed-torque"           # beyond the thesis: held to targets of its own
TESTBENCH_CONTROLLERS = ("pi", "adaptive", NEW_CONTROLLER)

def controller_at(log: LogData, cycle: int) -> str | None:
    """The controller CTRL_STATUS reported last at or before `cycle`."""
    status = log.get("CTRL_STATUS")
    value = last_value_before(status.cycle, status["CONTROLLER"], cycle)
    return None if np.isnan(value) else NAME_OF_CONTROLLER.get(int(value))


def run_emulator_config(log: LogData) -> EmulatorConfig:
    """The plant a log's run emulated: the config file the runner wrote beside the log (the
    scenario's and the user's sections over the defaults); the defaults without one."""
    path = Path(log.path).parent / "emulator.toml"
    return load_emulator_config(path if path.is_file() else None)


def run_controller_config(log: LogData):
    """The controller configuration a log's run ran (the config file the runner wrote beside
    the log); the defaults without one."""
    from firmware_py.config import load_config
    path = Path(log.path).parent / "controller.toml"
    return load_config(path if path.is_file() else None)


def load_at(log: LogData, cycle: int) -> float | None:
    """The emulator load set last (EMU_CTRL SET_LOAD) before `cycle`; None on a log without one."""
    load = None
    for event in log.events_named("EMU_CTRL"):
        if event.cycle > cycle:
            break
        if int(event.values["COMMAND"]) == EmuCommand.SET_LOAD:
            load = round(event.values["LOAD_MASS"], 3)
    return load


def each_controller_and_load(run, loads):
    """For each controller of the run and each load: select it, set the load, yield both."""
    for controller in run.scenario.chosen(run):
        run.select(controller)
        for load in run.scenario.chosen_loads(run, loads):
            run.host.set_load(load)
            yield controller, load


def move_stroke(run, stroke_m: float, speed_m_s: float = 0.1, accel_s: float = 0.1, settle_s: float = 0.5,
                from_m: float | None = None) -> None:
    """Test bench: an SLS move to `stroke_m`, then rest for `settle_s`."""
    distance = abs(stroke_m - from_m) if from_m is not None else 0.3
    duration = max(distance / speed_m_s + accel_s, 2.0 * accel_s + 0.1)
    duration = round(duration, 3)
    run.host.waypoint((0.0, 0.0, stroke_m), segment_time_s=duration, accel_time_s=accel_s,
                      flags=WaypointFlag.LAST | WaypointFlag.START)
    run.wait_s(duration + settle_s)


def step_stroke(run, stroke_m: float, hold_s: float) -> None:
    """Test bench: a step reference to `stroke_m`, held `hold_s`."""
    run.host.waypoint((0.0, 0.0, stroke_m), segment_time_s=hold_s, accel_time_s=hold_s / 2,
                      flags=WaypointFlag.LAST | WaypointFlag.START | WaypointFlag.STEP)
    run.wait_s(hold_s + 0.05)
