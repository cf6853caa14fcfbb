"""The controller and the emulator take the same --pacing: CTRL_STATUS carries the
controller's, the emulator says a difference once, and a lockstep emulator's valves wait
out the controller's lockstep wait."""

from __future__ import annotations

import argparse

import can
import pytest

from plant_emulator.emulator import Emulator
from plant_emulator.params import LOCKSTEP_SYNC_TIMEOUT_PERIODS
from plant_emulator.params import load_config as load_emulator_config
from plant_emulator.process import configure_parser, load_run_config
from plant_emulator.rigs import make_rig
from protocol.codec import CODECS
from protocol.enums import Pacing
from tests.support.loops import bus_loop, cycles


def _controllers_status(pacing: str) -> can.Message:
    """The last CTRL_STATUS a controller looping in `pacing` sent."""
    loop, _, bus = bus_loop("testbench", "pi", pacing=pacing)
    cycles(loop, 40)
    codec = CODECS["CTRL_STATUS"]
    return can.Message(arbitration_id=codec.frame_id, data=bytearray(bus.last_sent[codec.frame_id]),
                       is_extended_id=False)


@pytest.mark.parametrize("pacing", ["realtime", "lockstep"])
def test_ctrl_status_carries_the_controllers_pacing(pacing):
    codec = CODECS["CTRL_STATUS"]
    values = codec.new_values()
    codec.decode_into(_controllers_status(pacing).data, values)
    assert Pacing(int(values[codec.index["PACING"]])) is Pacing[pacing.upper()]


@pytest.mark.parametrize("mine,expect_line", [("realtime", True), ("lockstep", False), (None, False)])
def test_the_emulator_says_a_controller_of_another_pacing_once(capsys, mine, expect_line):
    cfg = load_emulator_config()
    emulator = Emulator(None, make_rig("testbench", cfg), cfg, pacing=mine)
    status = _controllers_status("lockstep")
    capsys.readouterr()
    for _ in range(3):
        emulator.handle(status)
    lines = [line for line in capsys.readouterr().err.splitlines() if "--pacing" in line]
    assert lines == (["emulator: the controller runs --pacing lockstep, this emulator --pacing realtime: "
                      "start both with the same --pacing"] if expect_line else [])
    assert emulator.summary()["controller_pacing"] == "lockstep"


def _emulator_args(*argv: str):
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    return parser.parse_args(list(argv))


def test_a_lockstep_emulators_valves_wait_out_the_controllers_lockstep_wait(tmp_path):
    assert _emulator_args().pacing == "realtime"                   # the controller's default too
    assert load_run_config(_emulator_args()).nodes.sync_timeout_periods == 3.0
    lockstep = load_run_config(_emulator_args("--pacing", "lockstep"))
    assert lockstep.nodes.sync_timeout_periods == LOCKSTEP_SYNC_TIMEOUT_PERIODS
    given = load_run_config(_emulator_args("--pacing", "lockstep", "--sync-watchdog-periods", "40"))
    assert given.nodes.sync_timeout_periods == 40.0
    config = tmp_path / "emulator.toml"
    config.write_text("[nodes]\nsync_timeout_periods = 12.0\n")             # the user's file wins
    assert load_run_config(_emulator_args("--pacing", "lockstep", "--config", str(config))).nodes \
        .sync_timeout_periods == 12.0
