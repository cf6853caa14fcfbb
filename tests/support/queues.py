"""A controller's waypoint queue and rig model without a controller: the capacity check's tests."""

from firmware_py.config import load_config
from firmware_py.rig_model import HexapodModel, TestbenchModel
from firmware_py.supervision.waypoints import WaypointQueue
from protocol.enums import Ack, State, WaypointFlag

LAST = int(WaypointFlag.LAST)
FAST = {"waypoints": {"velocity_max_mm_s": 3000.0}}     # the speed guard out of the way


def waypoint_queue(rig: str, overrides: dict | None = None):
    """(the queue, the rig model) of the packaged config with `overrides`, the speed guard off."""
    cfg = load_config(overrides={**FAST, **(overrides or {})})
    model = HexapodModel(cfg, 0.002) if rig == "hexapod" else TestbenchModel(cfg, 0.002)
    return WaypointQueue(cfg.waypoints, model.check), model


def commit(queue, model, seq: int, pose, segment_s: float, accel_s: float, flags: int = LAST,
           load_kg: float = 0.0) -> Ack:
    """Stage `pose` (x, y, z, roll, pitch, yaw) under SEQ's TAG and commit it from home."""
    queue.stage_position(seq, *pose[:3])
    queue.stage_rotation(seq, *pose[3:])
    return queue.commit(seq, seq, segment_s, accel_s, flags, State.READY, model.home_strokes, load_kg)
