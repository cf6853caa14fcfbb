"""What the controller says about itself after every update: written by the controller only,
read by the loop (CTRL_STATUS, CTRL_ACK, EMCY, its log), the summary, the benches and the
tests. Nothing outside reaches into the controller's parts for these.

Arrays are views of the controller's own state, made once (reading them allocates nothing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.enums import Fault, State


@dataclass(slots=True)
class ControllerStatus:
    rig: str                            # "testbench" or "hexapod"
    n_legs: int
    n_nodes: int                        # the rig's nodes on the bus: its legs, and the IMU on the hexapod
    state: State = State.BOOT
    fault: Fault = Fault.NONE           # the latched fault (NONE outside FAULT and ESTOP)
    fault_leg: int = 0                  # the leg (1..n) it was isolated to, 0: none
    kind: int = 0                       # the controller running (CTRL_STATUS.CONTROLLER)
    active_waypoint: int = 0            # SEQ of the waypoint being played
    queue_free: int = 0                 # free places in the waypoint queue (CTRL_ACK.QUEUE_FREE)
    cycles: int = 0
    faults: int = 0                     # faults latched since start
    restart_requests: int = 0           # RESETs accepted: each asks the NMT master to start nodes that rebooted
    moving: bool = False                # a trajectory is being played
    time_scaled: bool = False           # ... under the online time-scaling rule (while played)
    time_rate: float = 1.0              # its clock's rate, fraction of full speed (1 while none is played)
    motion_time_periods: float = 0.0    # its clock tau, in periods since its start (0 while none is played)
    testing: bool = False               # an identification test (HOST_TEST) drives the valve
    initialised: bool = False           # a complete set of measurements has come since start or RESET
    overruns_in_row: int = 0
    supply_configured_pa: float = 0.0   # the supply the actuator model assumes
    supply_measured_pa: float = math.nan  # the P-port transducers' mean at rest (NaN while moving)
    # per leg (views)
    reference_m: np.ndarray = None      # the joint reference of this cycle
    hold_m: np.ndarray = None           # where the legs are held when no trajectory plays
    position_m: np.ndarray = None       # the Kalman filters' position estimates
    error_m: np.ndarray = None          # reference - measured position
    spool: np.ndarray = None            # the controller's valve input, fraction of full input
    load_mass_kg: np.ndarray = None     # the RLS estimate of each leg's load (eq. 7.33-7.37)
    load_pressure_pa: np.ndarray = None # the indirect load pressure (eq. 7.38-7.39)
    friction_n: np.ndarray = None       # the seals' friction from the LuGre observer (eq. 7.30-7.32)
    residual_ratio: np.ndarray = None   # each actuator residual's |r| / threshold
    missing_in_row: np.ndarray = None   # cycles in a row without a valid LEG_STATE
    rejected_in_row: np.ndarray = None  # ... of which a frame came and was rejected
    # the hexapod (views; None on the test bench)
    pose: np.ndarray = None             # DK of the measured strokes: position, quaternion (w, x, y, z)
    reference_pose: np.ndarray = None   # DK of the reference strokes
    attitude_mismatch_rad: float = 0.0  # the encoders' DK attitude against the IMU's, last sample
    payload_mass_kg: float = math.nan   # the payload identified from the load cells (NaN: not estimated)
    payload_com_m: np.ndarray = None    # ... its centre of mass in the platform's frame (NaN: not placed)
    margins: object = None              # supervision.diagnostics.FalseAlarmMargins
