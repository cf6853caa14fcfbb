"""`hydrapod design tightness`: whether the capacity check is tight at a point of the envelope
(15 % faster than the plan is refused or saturates; the plan within 15 % of the fastest timing
that completes within 10 mm, the check opened). The whole envelope's table is
docs/MEASUREMENTS.md's; bad arguments: tests/project/test_cli_error_paths.py."""

import json
import math

import numpy as np
import pytest

from hil.cli import main
from hil.design.simulate import SETTLE_S, point_configs, thesis_motions
from hil.design.tightness import TIGHT_FACTOR, Tightness, opened_run
from hil.in_process import PERIOD_S


def _row(planned, fastest, refused=True, saturated_ms=0.0, completes=True):
    return Tightness("circle", 0.0, 25.0, planned, refused, saturated_ms, 12.0, 4.0, fastest, 9.0,
                     planned_completes=completes)


def test_tight_needs_the_faster_timing_to_exceed_and_the_plan_near_the_fastest():
    assert _row(1.0, 0.9).tight
    assert _row(1.0, 0.9, refused=False, saturated_ms=4.0).tight        # accepted, but a valve at its limit
    assert not _row(1.0, 0.9, refused=False).tight                      # 15 % faster neither refused nor limited
    assert not _row(1.0, 1.0 / (TIGHT_FACTOR + 0.01)).tight              # padded
    assert _row(1.0, 1.05).tight                                        # the run at P slowed by its clock, within 15 %
    assert not _row(1.0, 1.05, completes=False).tight                   # optimistic: the run at P misses the bound
    assert not _row(1.0, TIGHT_FACTOR + 0.01).tight                     # optimistic beyond 15 %
    assert math.isnan(_row(math.nan, math.nan).ratio)


@pytest.mark.slow                       # in process: the plan, then a handful of emulated movements
def test_the_circle_at_40_bar_is_planned_tight(capsys):
    assert main(["design", "tightness", "--movements", "circle", "--payload-kg", "0", "--supply-bar", "40",
                 "--workers", "1", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["faster_refused"]
    assert row["planned_error_mm"] <= 10.0
    assert 1.0 / TIGHT_FACTOR <= row["ratio"] <= TIGHT_FACTOR and row["tight"]


@pytest.mark.slow                       # in process: one emulated movement
def test_a_run_whose_clock_slows_is_played_to_its_end_and_counted_as_run():
    # the diagonal at 0.8 x its timing with 0 kg at 40 bar, the check opened: the valves draw
    # the accumulator down to the time scaling's share and the clock slows (1.8 s lost here)
    cfg, emulator = point_configs(0.0, 40.0)
    motion = thesis_motions()["diagonal"]
    run = opened_run(cfg, emulator, motion, 0.0, 0.8)
    assert run.completed and run.clock_lost_s > 0.5
    assert run.stretch == pytest.approx(1.0 + run.clock_lost_s / run.planned_s) and 0.8 * run.stretch > 1.0
    # recorded until SETTLE_S after the reference has played its last point, not its timing's end
    assert len(run.reference_m) * PERIOD_S == pytest.approx(run.planned_s + run.clock_lost_s + SETTLE_S,
                                                             abs=2 * PERIOD_S)
    assert np.allclose(run.reference_m[-1], motion.parts[-1][-1], atol=1e-4)
