"""The capacity check carries the supply's state from one motion to the next: the oil a
queued or running motion leaves drawn from the accumulator is where the next one starts,
and the pump refills it while nothing moves (firmware_py/controller.py, waypoints.py)."""

from firmware_py.config import load_config
from hil.in_process import PERIOD_S, InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol.enums import Ack, WaypointFlag
from tests.support.queues import commit, waypoint_queue

CHAIN = int(WaypointFlag.START | WaypointFlag.LAST)
RISE_M, MOVE_S, ACCEL_S = 0.15, 0.5, 0.05


def test_back_to_back_motions_that_each_fit_drain_the_accumulator_together():
    queue, model = waypoint_queue("hexapod")
    x, y, z = model.home_pose
    results, drawn = [], []
    for k in range(8):
        results.append(commit(queue, model, k, (x, y, z + (RISE_M if k % 2 == 0 else 0.0), 0.0, 0.0, 0.0),
                               MOVE_S, ACCEL_S, CHAIN))
        if results[-1] is not Ack.ACCEPTED:
            break
        drawn.append(queue.queue[-1].drawn_after_m3)
    assert results[:-1] == [Ack.ACCEPTED] * (len(results) - 1) and results[-1] is Ack.BEYOND_CAPACITY
    assert drawn == sorted(drawn) and drawn[0] > 0.0 and queue.time_scale_needed > 1.0
    assert len(results) % 2 == 1                         # the refused one is a rise from home ...
    fresh, model = waypoint_queue("hexapod")                     # ... which alone, the supply full, fits
    assert commit(fresh, model, 0, (x, y, z + RISE_M, 0.0, 0.0, 0.0), MOVE_S, ACCEL_S, CHAIN) is Ack.ACCEPTED


SMALL_ACCUMULATOR = {"power_unit": {"accumulator_gas_cm3": 900.0}}    # a rise and a descent leave too little


def test_the_controller_starts_the_next_motion_from_the_oil_drawn_and_refills_it_at_rest():
    loop = InProcessLoop(load_config(overrides=SMALL_ACCUMULATOR), load_emulator_config(overrides=SMALL_ACCUMULATOR),
                         "computed-torque")
    loop.activate(50)
    x, y, z = loop.ctl.rig.home_pose
    up, home = (x, y, z + RISE_M), (x, y, z)
    sent = 0
    while loop.send_waypoint(up if sent % 2 == 0 else home, MOVE_S, ACCEL_S, CHAIN) is Ack.ACCEPTED:
        sent += 1
    assert sent == 2                                     # the second rise refused behind the first two
    for _ in range(int(round((sent * MOVE_S + 0.5) / PERIOD_S))):  # they run, to their end
        loop.cycle()
        if not loop.ctl.reference.moving:
            break
    assert not loop.ctl.reference.moving and not loop.faulted
    target = up
    refused = loop.send_waypoint(target, MOVE_S, ACCEL_S, CHAIN)
    assert refused is Ack.BEYOND_CAPACITY                 # right after: still drawn
    loop.cycles(int(round(1.0 / PERIOD_S)))              # the pump's 10 l/min refills it
    assert loop.send_waypoint(target, MOVE_S, ACCEL_S, CHAIN) is Ack.ACCEPTED
