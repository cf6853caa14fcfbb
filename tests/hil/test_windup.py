"""The PID's integral at a leg's force limit (docs/MEASUREMENTS.md "The integral at a leg's
limit"): a host's sideways move with 4.5 kg at 20 bar, sent faster than the capacity check
allows (the check opened), puts two legs at their pull limit with their spools inside u_max.
Wound up meanwhile, the integral swings the platform past the stop; stopped there, it does not."""

import numpy as np
import pytest

from hil.design.edge_moves import SETTLE_S, random_move
from hil.design.simulate import point_configs
from hil.design.tightness import open_check
from hil.in_process import PERIOD_S, InProcessLoop
from protocol.enums import Ack, WaypointFlag

MOVE_SEED, TIME_SCALE = 8, 1.4      # `design edge-moves`' move 1 of seed 8; its check's edge is ~2x
AFTER_S = 0.8


def _past_the_stop_mm(windup_capacity_pct: float) -> tuple[float, float]:
    """(the largest error while the reference moves, the largest past its end) [mm], emulator truth."""
    payload, supply, start, target, segment, accel = random_move(np.random.default_rng(MOVE_SEED))
    cfg, emulator = point_configs(payload, supply, {"windup_capacity_pct": windup_capacity_pct})
    loop = InProcessLoop(cfg, emulator, "computed-torque", payload, 1)
    open_check(loop)
    alone = int(WaypointFlag.START | WaypointFlag.LAST)
    loop.activate()
    loop.waypoint(start, 2.0, 0.5, alone)           # as `design edge-moves` starts it
    loop.cycles(round(SETTLE_S / PERIOD_S))
    assert loop.send_waypoint(target, segment * TIME_SCALE, accel * TIME_SCALE, alone) == Ack.ACCEPTED
    direction = (np.asarray(target) - np.asarray(start)) / np.linalg.norm(np.subtract(target, start))
    moving, past = 0.0, 0.0
    for k in range(round((segment * TIME_SCALE + AFTER_S) / PERIOD_S)):
        loop.cycle()
        position, _ = loop.rig.platform_pose()
        error_mm = (position - loop.status.reference_pose[:3]) * 1e3
        if k * PERIOD_S < segment * TIME_SCALE:
            moving = max(moving, float(np.max(np.abs(error_mm))))
        else:
            past = max(past, float(error_mm @ direction))            # beyond the target, along the move
    assert loop.status.fault.name == "NONE"
    return moving, past


@pytest.mark.slow                    # in process, two moves of a few seconds each
def test_an_integral_stopped_at_the_legs_limit_does_not_swing_the_platform_past_the_stop():
    stopped = _past_the_stop_mm(150.0)          # the packaged share
    wound = _past_the_stop_mm(1e5)              # never beyond: only a saturated valve stops it
    assert stopped[1] < 0.9 * wound[1]          # 10.3 against 12.0 mm
    assert stopped[0] <= wound[0] + 0.1         # and no worse while it moves (10.1 both)
