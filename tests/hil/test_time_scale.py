"""`hil run --time-scale`: the movements' timing, the thesis's at 1; refused by scenarios
without a movement to scale (one line, exit 2)."""

from __future__ import annotations

import copy

import pytest

from hil.cli import main
from hil.runner import RunOptions, run_scenario
from hil.scenarios import SCENARIOS
from program.errors import UserInputError


@pytest.mark.parametrize("name", ["pm-circle", "pm-diagonal"])
def test_the_movement_scales_from_the_thesis_timing(name):
    scenario = copy.copy(SCENARIOS[name])
    thesis = scenario.thesis_motion()
    for scale in (1.0, 2.5):
        scenario.time_scale = scale
        motion = scenario.motion()
        assert (motion.ta_s, motion.tm_s) == pytest.approx((thesis.ta_s * scale, thesis.tm_s * scale))
    assert (thesis.ta_s, thesis.tm_s) == (scenario.thesis["ta_s"], scenario.thesis["tm_s"])


def test_a_scenario_without_movements_refuses_a_time_scale(tmp_path, capsys):
    with pytest.raises(UserInputError, match="sha-step has no movement timing"):
        run_scenario(SCENARIOS["sha-step"], RunOptions(out_dir=tmp_path, time_scale=1.0))
    assert main(["hil", "run", "sha-step", "--time-scale", "1", "--out", str(tmp_path)]) == 2
    assert "--time-scale" in capsys.readouterr().err
    assert SCENARIOS["pm-circle"].time_scale == 1.0          # the registered default: the thesis's timing
